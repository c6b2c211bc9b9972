// The page at GET /: sends the chosen image to POST /localize?trace=…, then
// draws the query beside its candidates (thumbnails from
// GET /images/{id}/thumbnail), the vote race on two canvases and the time
// per stage. Errors of the API are shown as their message.
"use strict";

const $ = (id) => document.getElementById(id);
let queryBlob = null; // the image to send
let queryName = "";
let lastAnswer = null;
// What the server says (GET /map, GET /openapi.json); null until it has.
const server = {
  extractSide: null, // longer side a query is downscaled to (0: kept)
  thumbMin: null, // the thumbnail's `size` range
  thumbMax: null,
};

const COLORS = {
  leader: "#1f6feb",
  runner: "#d97706",
  mean: "#6b7280",
  full: "#9ca3af",
  stat: "#7c3aed",
  threshold: "#dc2626",
  stop: "#059669",
  tile: "#e5e7eb",
  axis: "#374151",
};

function showError(message) {
  const box = $("error");
  box.textContent = message;
  box.hidden = false;
}

function clearError() {
  $("error").hidden = true;
  $("error").textContent = "";
}

// The message of an error answer: the API's JSON `error.message`, or what
// the browser says.
async function errorOf(response) {
  try {
    const body = await response.json();
    if (body && body.error) {
      return `${body.error.message} (${response.status} ${body.error.code})`;
    }
  } catch (_) {
    // not JSON
  }
  return `the service answered ${response.status} ${response.statusText}`;
}

function fmt(x, digits = 3) {
  if (x === null || x === undefined || Number.isNaN(x)) return "–";
  if (Math.abs(x) >= 1000 || Number.isInteger(x)) return String(Math.round(x * 100) / 100);
  return Number(x).toPrecision(digits);
}

function setQuery(blob, name) {
  queryBlob = blob;
  queryName = name;
  $("submit").disabled = !blob;
  $("status").textContent = blob ? `Ready: ${name}` : "";
}

// --- settings from the API itself -----------------------------------------

async function loadMapAndRules() {
  try {
    const r = await fetch("/map");
    if (r.ok) {
      const m = await r.json();
      const id = m.identity;
      $("map-info").textContent =
        `Map “${id.name}”: ${id.images} images, ${id.words} visual words.`;
      $("map-image").max = String(Math.max(0, id.images - 1));
      server.extractSide = m.query_extract.max_side;
    } else {
      $("map-info").textContent = `Map not available: ${await errorOf(r)}`;
    }
  } catch (e) {
    $("map-info").textContent = `Map not available: ${e.message}`;
  }
  let doc;
  try {
    doc = await (await fetch("/openapi.json")).json();
  } catch (_) {
    return; // the default rule still works; no map image as a query
  }
  try {
    const params = doc.paths["/localize"].post.parameters;
    const rule = params.find((p) => p.name === "rule");
    for (const name of rule.schema.enum) {
      const o = document.createElement("option");
      o.value = name;
      o.textContent = name;
      $("rule").appendChild(o);
    }
    $("rule").title = rule.description;
  } catch (_) {
    // the default rule still works
  }
  try {
    const params = doc.paths["/images/{id}/thumbnail"].get.parameters;
    const size = params.find((p) => p.name === "size").schema;
    server.thumbMin = size.minimum;
    server.thumbMax = size.maximum;
  } catch (_) {
    // no map image as a query, no inlier lines
  }
}

// --- choosing the image ----------------------------------------------------

function wireInputs() {
  $("file").addEventListener("change", () => {
    const f = $("file").files[0];
    if (f) setQuery(f, f.name);
  });
  const zone = $("drop-zone");
  zone.addEventListener("dragover", (e) => {
    e.preventDefault();
    zone.classList.add("over");
  });
  zone.addEventListener("dragleave", () => zone.classList.remove("over"));
  zone.addEventListener("drop", (e) => {
    e.preventDefault();
    zone.classList.remove("over");
    const f = e.dataTransfer.files[0];
    if (f) setQuery(f, f.name);
  });
  $("use-map-image").addEventListener("click", async () => {
    clearError();
    const id = $("map-image").value.trim();
    if (!/^\d+$/.test(id)) {
      showError("Give a map image id: a whole number from 0.");
      return;
    }
    // the map image at the size SIFT sees of a query, as far as a thumbnail
    // can be that large
    const { extractSide, thumbMax } = server;
    if (extractSide === null || thumbMax === null) {
      showError("The map's settings are not known: reload the page once the map is loaded.");
      return;
    }
    const size = extractSide > 0 ? Math.min(extractSide, thumbMax) : thumbMax;
    const r = await fetch(`/images/${id}/thumbnail?size=${size}`);
    if (!r.ok) {
      showError(`Map image ${id}: ${await errorOf(r)}`);
      return;
    }
    setQuery(await r.blob(), `map image ${id}`);
  });
  $("query-form").addEventListener("submit", (e) => {
    e.preventDefault();
    localize();
  });
}

// --- the request -----------------------------------------------------------

function queryString() {
  const q = new URLSearchParams();
  const rule = $("rule").value;
  if (rule) q.set("rule", rule);
  const t = $("threshold").value.trim();
  if (t) q.set("threshold", t);
  const n = $("top_n").value.trim();
  if (n) q.set("top_n", n);
  const seed = $("seed").value.trim();
  if (seed) q.set("seed", seed);
  const budget = $("budget_ms").value.trim();
  if (budget) q.set("budget_ms", budget);
  q.set("verify", $("verify").checked ? "true" : "false");
  q.set("trace", $("full").checked ? "full" : "true");
  return q.toString();
}

async function localize() {
  if (!queryBlob) return;
  clearError();
  $("submit").disabled = true;
  $("status").textContent = `Localizing ${queryName}…`;
  try {
    const body = new FormData();
    body.append("image", queryBlob, queryName || "query");
    const started = performance.now();
    const r = await fetch(`/localize?${queryString()}`, { method: "POST", body });
    if (!r.ok) {
      showError(await errorOf(r));
      $("status").textContent = "";
      return;
    }
    const answer = await r.json();
    const wall = performance.now() - started;
    lastAnswer = answer;
    $("status").textContent =
      `Answered in ${fmt(wall, 3)} ms (browser to browser); seed ${answer.seed}.`;
    await render(answer);
  } catch (e) {
    showError(`The request failed: ${e.message}`);
    $("status").textContent = "";
  } finally {
    $("submit").disabled = false;
  }
}

// --- drawing the answer ----------------------------------------------------

async function render(answer) {
  $("results").hidden = false;
  await drawQuery(answer);
  drawCandidates(answer);
  $("match-box").hidden = true;
  const top = answer.candidates[0];
  if (top && matchesOf(answer, top.id)) await drawMatches(answer, top);
  drawRace(answer);
  drawTimings(answer);
}

async function drawQuery(answer) {
  const canvas = $("query-canvas");
  const ctx = canvas.getContext("2d");
  const w = answer.image.width;
  const h = answer.image.height;
  $("query-caption").textContent = `${queryName} (${w}×${h})`;
  try {
    const bitmap = await createImageBitmap(queryBlob);
    const scale = Math.min(1, 320 / Math.max(bitmap.width, bitmap.height));
    canvas.width = Math.round(bitmap.width * scale);
    canvas.height = Math.round(bitmap.height * scale);
    ctx.drawImage(bitmap, 0, 0, canvas.width, canvas.height);
  } catch (_) {
    // a format the browser cannot show (PNM, TIFF): the service read it
    canvas.width = 320;
    canvas.height = Math.round((320 * h) / Math.max(w, 1)) || 240;
    ctx.fillStyle = "#f3f4f6";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    ctx.fillStyle = COLORS.axis;
    ctx.fillText("(the browser cannot show this format)", 10, 20);
  }
}

function drawCandidates(answer) {
  const list = $("candidates");
  list.replaceChildren();
  if (answer.candidates.length === 0) {
    const li = document.createElement("li");
    li.className = "empty";
    li.textContent = "No candidates: no features were found in the image.";
    list.appendChild(li);
    return;
  }
  const fullTop = answer.trace && answer.trace.full && answer.trace.full.candidates[0];
  for (const c of answer.candidates) {
    const li = document.createElement("li");
    li.className = "candidate";
    const fig = document.createElement("figure");
    const img = document.createElement("img");
    img.src = `/images/${c.id}/thumbnail`;
    img.alt = `Map image ${c.id}: ${c.place || c.name}`;
    img.loading = "eager";
    img.addEventListener("error", () => {
      img.replaceWith(Object.assign(document.createElement("div"), {
        className: "no-thumb",
        textContent: "no thumbnail",
      }));
    });
    const cap = document.createElement("figcaption");
    const lines = [
      `#${c.rank} ${c.place ? c.place + " · " : ""}${c.name}`,
      answer.verified === undefined
        ? `score ${fmt(c.score)}`
        : `${c.inliers ?? 0} inliers${c.verified ? " ✔ verified" : ""}` +
          (c.scale === undefined ? "" : ` · scale ${c.scale.toFixed(2)}`) +
          ` · votes ${fmt(c.votes)}`,
    ];
    if (fullTop && c.rank === 1) {
      lines.push(fullTop.id === c.id ? "full search agrees" : `full search: #1 is ${fullTop.name}`);
    }
    for (const text of lines) {
      const span = document.createElement("span");
      span.textContent = text;
      cap.appendChild(span);
    }
    fig.append(img, cap);
    li.appendChild(fig);
    if (matchesOf(answer, c.id)) {
      const b = document.createElement("button");
      b.type = "button";
      b.className = "show-matches";
      b.textContent = "Show matches";
      b.setAttribute("aria-label", `Show the inlier matches of candidate ${c.rank}`);
      b.addEventListener("click", () => drawMatches(answer, c));
      li.appendChild(b);
    }
    list.appendChild(li);
  }
}

function matchesOf(answer, id) {
  const m = answer.trace && answer.trace.matches;
  return m ? m.find((e) => e.id === id) : undefined;
}

function loadImage(src) {
  return new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => resolve(img);
    img.onerror = () => reject(new Error(`cannot load ${src}`));
    img.src = src;
  });
}

// The query beside candidate `c`, with a line between the two keypoints of
// every inlier. Positions are in each image's extraction frame: the image
// downscaled so its longer side is at most `frame_side`; a map thumbnail of
// that size is that frame.
async function drawMatches(answer, c) {
  const box = $("match-box");
  const canvas = $("match-canvas");
  canvas.dataset.lines = "0";
  const m = matchesOf(answer, c.id);
  const side = answer.trace.frame_side;
  if (!m || !(side >= server.thumbMin && side <= server.thumbMax)) {
    box.hidden = true;
    return;
  }
  box.hidden = false;
  $("match-title").textContent =
    `Inlier matches: query and #${c.rank} ${c.place || c.name} (${c.inliers} inliers; ${m.lines.length} inlier pairs drawn)`;
  let query;
  let map;
  try {
    [query, map] = await Promise.all([
      createImageBitmap(queryBlob),
      loadImage(`/images/${c.id}/thumbnail?size=${side}`),
    ]);
  } catch (e) {
    showError(`Cannot draw the matches: ${e.message}`);
    return;
  }
  const gap = 8;
  const ratio = window.devicePixelRatio || 1;
  canvas.style.width = "100%";
  const width = canvas.clientWidth || 600;
  const half = (width - gap) / 2;
  const qs = half / query.width;
  const ms = half / map.naturalWidth;
  const height = Math.max(query.height * qs, map.naturalHeight * ms);
  canvas.style.height = `${height}px`;
  canvas.width = Math.round(width * ratio);
  canvas.height = Math.round(height * ratio);
  const ctx = canvas.getContext("2d");
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  ctx.drawImage(query, 0, 0, query.width * qs, query.height * qs);
  ctx.drawImage(map, half + gap, 0, map.naturalWidth * ms, map.naturalHeight * ms);
  // query frame → drawn query: the frame is the decoded image scaled by f
  const w = answer.image.width;
  const h = answer.image.height;
  const f = side > 0 ? Math.min(1, side / Math.max(w, h)) : 1;
  const qx = (x) => (x / f) * (query.width / w) * qs;
  ctx.lineWidth = 1.5;
  m.lines.forEach(([x1, y1, x2, y2], i) => {
    ctx.strokeStyle = `hsl(${(i * 47) % 360}, 85%, 50%)`;
    ctx.beginPath();
    ctx.moveTo(qx(x1), qx(y1));
    ctx.lineTo(half + gap + x2 * ms, y2 * ms);
    ctx.stroke();
  });
  canvas.dataset.lines = String(m.lines.length);
}

// A canvas sized to its box, sharp on high-density screens.
function prepare(canvas, height) {
  const ratio = window.devicePixelRatio || 1;
  canvas.style.width = "100%";
  const width = canvas.clientWidth || 600;
  canvas.style.height = `${height}px`;
  canvas.width = Math.round(width * ratio);
  canvas.height = Math.round(height * ratio);
  const ctx = canvas.getContext("2d");
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  ctx.clearRect(0, 0, width, height);
  ctx.font = "12px system-ui, sans-serif";
  return { ctx, width, height };
}

// Axes and scales of a chart over features 0..maxX.
function frame(ctx, width, height, maxX, maxY, label) {
  const pad = { left: 52, right: 12, top: 14, bottom: 30 };
  const x = (f) => pad.left + (f / Math.max(maxX, 1)) * (width - pad.left - pad.right);
  const y = (v) => height - pad.bottom - (v / (maxY || 1)) * (height - pad.top - pad.bottom);
  ctx.strokeStyle = COLORS.axis;
  ctx.lineWidth = 1;
  ctx.beginPath();
  ctx.moveTo(pad.left, pad.top);
  ctx.lineTo(pad.left, height - pad.bottom);
  ctx.lineTo(width - pad.right, height - pad.bottom);
  ctx.stroke();
  ctx.fillStyle = COLORS.axis;
  ctx.textAlign = "right";
  ctx.fillText(fmt(maxY, 3), pad.left - 4, pad.top + 8);
  ctx.fillText("0", pad.left - 4, height - pad.bottom);
  ctx.textAlign = "center";
  ctx.fillText("0", pad.left, height - pad.bottom + 14);
  ctx.fillText(String(maxX), width - pad.right - 10, height - pad.bottom + 14);
  ctx.fillText(label, (pad.left + width - pad.right) / 2, height - 4);
  return { x, y, pad };
}

function line(ctx, points, x, y, value, color, dashed = false) {
  const pts = points.filter((p) => value(p) !== undefined && value(p) !== null);
  if (pts.length === 0) return;
  ctx.strokeStyle = color;
  ctx.lineWidth = 2;
  ctx.setLineDash(dashed ? [5, 4] : []);
  ctx.beginPath();
  pts.forEach((p, i) => {
    const px = x(p.features);
    const py = y(value(p));
    if (i === 0) ctx.moveTo(px, py);
    else ctx.lineTo(px, py);
  });
  ctx.stroke();
  ctx.setLineDash([]);
}

function marker(ctx, xPos, top, bottom, color, text, dashed) {
  const right = ctx.canvas.width / (window.devicePixelRatio || 1);
  ctx.strokeStyle = color;
  ctx.lineWidth = 2;
  ctx.setLineDash(dashed ? [4, 4] : []);
  ctx.beginPath();
  ctx.moveTo(xPos, top);
  ctx.lineTo(xPos, bottom);
  ctx.stroke();
  ctx.setLineDash([]);
  ctx.fillStyle = color;
  // the label on the side with room for it
  const room = xPos + 8 + ctx.measureText(text).width < right;
  ctx.textAlign = room ? "left" : "right";
  ctx.fillText(text, room ? xPos + 4 : xPos - 4, top + 10);
}

// The warm-up, before the rule is consulted, shaded.
function warmUp(ctx, x, pad, height, features) {
  if (!features) return;
  ctx.fillStyle = "rgba(107, 114, 128, 0.12)";
  ctx.fillRect(x(0), pad.top, x(features) - x(0), height - pad.top - pad.bottom);
  ctx.fillStyle = "#4b5563";
  ctx.textAlign = "left";
  ctx.fillText("warm-up", x(0) + 4, height - pad.bottom - 6);
}

function drawRace(answer) {
  const raceCanvas = $("race-chart");
  const statCanvas = $("stat-chart");
  raceCanvas.dataset.drawn = "false";
  const trace = answer.trace;
  if (!trace || trace.points.length === 0) {
    $("race-summary").textContent = "No features were voted, so there is no race to show.";
    prepare(raceCanvas, 40);
    prepare(statCanvas, 10);
    return;
  }
  const full = trace.full;
  const stopAt = answer.stop.at_feature;
  const maxX = Math.max(stopAt, full ? full.features : 0, answer.features.total, 1);
  const all = trace.points.concat(full ? full.points : []);
  const maxY = Math.max(...all.map((p) => p.leader_votes), 1e-9);

  // votes
  {
    const { ctx, width, height } = prepare(raceCanvas, 260);
    const { x, y, pad } = frame(ctx, width, height, maxX, maxY, "features voted");
    warmUp(ctx, x, pad, height, Math.min(trace.warm_up, maxX));
    ctx.fillStyle = COLORS.axis;
    ctx.save();
    ctx.translate(12, height / 2);
    ctx.rotate(-Math.PI / 2);
    ctx.textAlign = "center";
    ctx.fillText("summed votes", 0, 0);
    ctx.restore();
    for (const end of trace.tile_ends.slice(0, -1)) {
      ctx.strokeStyle = COLORS.tile;
      ctx.beginPath();
      ctx.moveTo(x(end), pad.top);
      ctx.lineTo(x(end), height - pad.bottom);
      ctx.stroke();
    }
    if (full) {
      line(ctx, full.points, x, y, (p) => p.leader_votes, COLORS.full, true);
      line(ctx, full.points, x, y, (p) => p.runner_up_votes, COLORS.full, true);
      marker(ctx, x(full.features), pad.top, height - pad.bottom, COLORS.full,
        "full search ends", true);
    }
    line(ctx, trace.points, x, y, (p) => p.mean_votes, COLORS.mean);
    line(ctx, trace.points, x, y, (p) => p.runner_up_votes, COLORS.runner);
    line(ctx, trace.points, x, y, (p) => p.leader_votes, COLORS.leader);
    marker(ctx, x(stopAt), pad.top + 14, height - pad.bottom, COLORS.stop,
      `${answer.stop.kind === "rule" ? "rule stopped" : answer.stop.kind} at ${stopAt}`, false);
  }

  // the rule's statistic against its threshold
  const stats = trace.points.filter((p) => p.statistic !== undefined);
  if (stats.length > 0) {
    const { ctx, width, height } = prepare(statCanvas, 180);
    const top = Math.max(...stats.map((p) => Math.max(p.statistic, p.threshold)), 1e-9);
    const { x, y, pad } = frame(ctx, width, height, maxX, top * 1.05,
      `${answer.rule.name}: statistic against its ${answer.rule.parameter || "threshold"}`);
    warmUp(ctx, x, pad, height, Math.min(trace.warm_up, maxX));
    line(ctx, stats, x, y, (p) => p.threshold, COLORS.threshold, true);
    line(ctx, stats, x, y, (p) => p.statistic, COLORS.stat);
    marker(ctx, x(stopAt), pad.top, height - pad.bottom, COLORS.stop, "stop", false);
    statCanvas.hidden = false;
  } else {
    prepare(statCanvas, 10);
    statCanvas.hidden = true;
  }
  raceCanvas.dataset.drawn = "true";

  const f = answer.features;
  const leaderChanges = trace.points.reduce(
    (n, p, i, a) => n + (i > 0 && p.leader !== a[i - 1].leader ? 1 : 0), 0);
  const of = answer.tiles.extracted < answer.tiles.total ? `about ${f.total} (estimated)` : `${f.total}`;
  let text = `Stopped at feature ${stopAt} of ${of}; ${answer.stop.detail}. ` +
    (trace.warm_up > 0 ? `The rule was first consulted after ${trace.warm_up} features (warm-up). ` : "") +
    `The leader changed ${leaderChanges} time${leaderChanges === 1 ? "" : "s"} in the sampled points.`;
  if (full) {
    const a = answer.trace.full.candidates[0];
    text += ` The full search voted all ${full.features} features` +
      (a ? `; its best candidate is ${a.name}.` : ".");
  }
  $("race-summary").textContent = text;
}

function drawTimings(answer) {
  const t = answer.timings_ms;
  const stages = ["decode", "extract", "quantize", "vote", "verify"];
  const box = $("timings");
  box.replaceChildren();
  const bar = document.createElement("div");
  bar.className = "bar";
  bar.setAttribute("role", "img");
  bar.setAttribute("aria-label", stages.map((s) => `${s} ${fmt(t[s])} ms`).join(", "));
  const table = document.createElement("table");
  const head = table.createTHead().insertRow();
  for (const h of ["stage", "ms", "share"]) {
    const th = document.createElement("th");
    th.textContent = h;
    head.appendChild(th);
  }
  const body = table.createTBody();
  for (const s of stages) {
    const share = t.total > 0 ? t[s] / t.total : 0;
    const seg = document.createElement("span");
    seg.className = `seg ${s}`;
    seg.style.width = `${(share * 100).toFixed(2)}%`;
    seg.title = `${s}: ${fmt(t[s])} ms`;
    bar.appendChild(seg);
    const row = body.insertRow();
    row.insertCell().textContent = s;
    row.insertCell().textContent = fmt(t[s]);
    row.insertCell().textContent = `${(share * 100).toFixed(1)} %`;
  }
  const total = body.insertRow();
  total.insertCell().textContent = "total";
  total.insertCell().textContent = fmt(t.total);
  total.insertCell().textContent = "";
  box.append(bar, table);
  const f = answer.features;
  $("usage").textContent =
    `Features: ${f.used} voted of ${f.extracted} extracted, ${f.total} in the image` +
    `${answer.tiles.extracted < answer.tiles.total ? " (estimated)" : ""}: ` +
    `${(f.fraction * 100).toFixed(1)} % used. ` +
    `Tiles: ${answer.tiles.extracted} of ${answer.tiles.total} extracted (grid ${answer.tiles.grid})` +
    (answer.tiles.saved_ms > 0 ? `, about ${fmt(answer.tiles.saved_ms)} ms of extraction saved.` : ".");
}

window.addEventListener("resize", () => {
  if (lastAnswer) drawRace(lastAnswer);
});

document.addEventListener("DOMContentLoaded", () => {
  wireInputs();
  loadMapAndRules();
});
