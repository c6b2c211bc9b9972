#!/usr/bin/env bash
# End-to-end checks of `bowloc serve` with curl and jq: builds a small map
# from the rtabmap-loop dataset in a temporary folder, starts the real server
# on a free loopback port and checks every endpoint, the error paths and a
# graceful shutdown. The last line is `N passed, M failed`; the exit status is
# non-zero when anything failed.
#
# usage: tests/curl/run.sh [path/to/bowloc [path/to/datasets]]
#   (defaults: target/release/bowloc and ../shared/datasets beside the
#   repository)
set -uo pipefail

ROOT="$(cd "$(dirname "$0")/../.." && pwd)"
BIN="${1:-$ROOT/target/release/bowloc}"
DATASETS="${2:-$ROOT/../shared/datasets}"
# The servers started here read only the configuration written here.
for v in $(compgen -e | grep '^BOWLOC_'); do unset "$v"; done
RTAB="$DATASETS/rtabmap-loop"
GARDENS="$DATASETS/gardens-point"
# Measured: 43 of the 44 queries have a correct top candidate with this map
# (1000 words, k-means seed 1, the default rule place-z 2 after 20
# features, permutation seed 1; also 43 with rule none); the floor
# leaves a little slack.
MIN_CORRECT=40

passed=0
failed=0
ok() { passed=$((passed + 1)); echo "ok    $1"; }
fail() { failed=$((failed + 1)); echo "FAIL  $1${2:+: $2}"; }
check() { # check NAME COMMAND...: passes when the command succeeds
  local name=$1; shift
  if "$@"; then ok "$name"; else fail "$name"; fi
}
jqt() { jq -e "$@" >/dev/null; } # jqt FILTER FILE: the filter holds
finish() {
  echo "$passed passed, $failed failed"
  [ "$failed" -eq 0 ]
  exit $?
}

for tool in curl jq; do
  command -v "$tool" >/dev/null || { echo "$tool is missing (scripts/setup.sh installs it)"; fail "tools"; finish; }
done
[ -x "$BIN" ] || { fail "binary" "$BIN is not executable"; finish; }
[ -f "$RTAB/map.txt" ] || { fail "dataset" "$RTAB not found"; finish; }

TMP="$(mktemp -d)"
SERVER_PIDS=()
cleanup() {
  for pid in "${SERVER_PIDS[@]}"; do
    kill -0 "$pid" 2>/dev/null && kill -KILL "$pid" 2>/dev/null
  done
  rm -rf "$TMP"
}
trap cleanup EXIT

# --- a small map -------------------------------------------------------------
if ! "$BIN" vocab build --images "$RTAB/map.txt" --words 1000 --seed 1 \
      --out "$TMP/vocab.bowvoc" 2>"$TMP/build.log" \
   || ! "$BIN" map build --vocab "$TMP/vocab.bowvoc" --images "$RTAB/map.txt" \
      --out "$TMP/map.bowmap" --name rtabmap-loop 2>>"$TMP/build.log"; then
  cat "$TMP/build.log"; fail "build map"; finish
fi
ok "build a map of rtabmap-loop"

# write_config FILE WORKERS QUEUE DEADLINE_MS [MAX_FEATURES]
write_config() {
  cat >"$1" <<TOML
[server]
listen = "127.0.0.1:0"
workers = $2
log_format = "human"
[files]
vocabulary = "$TMP/vocab.bowvoc"
map = "$TMP/map.bowmap"
[limits]
body_bytes = 2000000
queue = $3
deadline_ms = $4
max_features = ${5:-4000}
[bootstrap]
enabled = false
TOML
}

# launch CONFIG LOG [DIR]: starts it (in DIR, default here; CONFIG "" names
# no file), sets PID and BASE once it listens.
launch() {
  (cd "${3:-.}" && exec "$BIN" serve ${1:+--config "$1"}) >"$2" 2>&1 &
  PID=$!
  SERVER_PIDS+=("$PID")
  local port="" i
  for i in $(seq 1 100); do
    port=$(grep -o 'listening on http://127.0.0.1:[0-9]*' "$2" | head -1 | sed 's/.*://')
    [ -n "$port" ] && break
    kill -0 "$PID" 2>/dev/null || break
    sleep 0.1
  done
  [ -n "$port" ] || { cat "$2"; return 1; }
  BASE="http://127.0.0.1:$port"
}

# start_server CONFIG LOG [DIR]: starts it, sets PID and BASE, waits for /readyz.
start_server() {
  launch "$1" "$2" "${3:-.}" || return 1
  local i
  for i in $(seq 1 300); do
    [ "$(curl -s -o /dev/null -w '%{http_code}' "$BASE/readyz")" = 200 ] && return 0
    kill -0 "$PID" 2>/dev/null || break
    sleep 0.1
  done
  cat "$2"
  return 1
}

# startup_fails NAME TEXT CONFIG [VAR=VALUE...] [-- SERVE-FLAGS...]: `serve`
# exits non-zero within 60 s and its output contains TEXT.
startup_fails() {
  local name=$1 text=$2 config=$3 out rc vars=()
  shift 3
  while [ $# -gt 0 ] && [ "$1" != -- ]; do vars+=("$1"); shift; done
  [ "${1:-}" = -- ] && shift
  out=$(env "${vars[@]}" timeout 60 "$BIN" serve --config "$config" "$@" 2>&1)
  rc=$?
  if [ "$rc" != 0 ] && [ "$rc" != 124 ] && grep -qF -- "$text" <<<"$out"; then
    ok "start-up fault: $name → exit $rc, names \"$text\""
  else
    fail "start-up fault: $name" "exit $rc, want non-zero naming \"$text\"; output: $(tail -1 <<<"$out")"
  fi
}

write_config "$TMP/config.toml" 2 8 10000
if start_server "$TMP/config.toml" "$TMP/server.log"; then
  ok "server starts and becomes ready ($BASE)"
else
  fail "server starts and becomes ready"; finish
fi
MAIN_BASE=$BASE
MAIN_PID=$PID
# each of the 2 workers extracted once before the server said it was ready
warmed_before_ready() {
  awk '/workers warmed up workers=2 / {w = NR} / ready map=/ {r = NR} END {exit !(w && r && w < r)}' "$TMP/server.log"
}
check "both workers warmed up before the server was ready" warmed_before_ready

# req OUT ARGS...: curl, body to OUT, prints the status code.
req() { local out=$1; shift; curl -s -o "$out" -w '%{http_code}' "$@"; }
IMG="$RTAB/images/45.jpg"
B="$TMP/body"

# --- health, readiness, map, openapi -----------------------------------------
check "GET /healthz is 200 alive" test "$(req "$B" "$BASE/healthz")/$(jq -r .status "$B")" = "200/alive"
check "GET /readyz is 200 ready" test "$(req "$B" "$BASE/readyz")/$(jq -r .status "$B")" = "200/ready"
check "GET /map names the loaded map" test \
  "$(req "$B" "$BASE/map")/$(jq -r '.identity.name, .identity.images, .map.images' "$B" | paste -sd/)" = "200/rtabmap-loop/40/40"
# the pass is on by default, but this map has no ORB side: served without it,
# a warning naming the command that builds one, and no orb_pass in /map
check "a map without its ORB side: start-up warns how to build it" \
  grep -q "the map has no ORB side, so the ORB pass is off: build it with .bowloc map orb-pass" "$TMP/server.log"
check "GET /map has no orb_pass without a side" test "$(req "$B" "$BASE/map")/$(jq -r 'has("orb_pass")' "$B")" = "200/false"
req "$TMP/openapi.json" "$BASE/openapi.json" >/dev/null
check "GET /openapi.json equals docs/openapi.json" cmp -s "$TMP/openapi.json" "$ROOT/docs/openapi.json"

# --- localization ------------------------------------------------------------
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?top_n=3&seed=7")
check "raw upload is 200" test "$status" = 200
check "answer has 3 ranked candidates" test "$(jq -r '[.candidates[].rank] | join(",")' "$B")" = "1,2,3"
check "answer reports features, rule, stop, seed, timings, map" jqt '
  .features.total > 0 and .features.used <= .features.total and .features.fraction > 0
  and .rule.name == "place-z" and .rule.value == 2.25 and (.stop.kind | IN("rule","exhausted","deadline"))
  and .stop.at_feature == .features.used and .seed == 7
  and .timings_ms.total > 0 and .timings_ms.extract > 0
  and .map.name == "rtabmap-loop" and .map.images == 40 and .map.words == 1000
  and (.map.vocabulary | length) == 16 and .image.width == 512' "$B"
cp "$B" "$TMP/first.json"
# the answer's seed and tiles.grid replay it (with a learned plan,
# search.tiles ending in ,auto, the grid names the plan it chose)
grid=$(jq -r '.tiles.grid | @uri' "$TMP/first.json")
req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?top_n=3&seed=7&tiles=$grid" >/dev/null
check "same seed and grid give the same candidates" test \
  "$(jq -c '[.candidates[] | [.id, .score]]' "$B")" = "$(jq -c '[.candidates[] | [.id, .score]]' "$TMP/first.json")"
status=$(req "$B" -F "image=@$IMG" "$BASE/localize?top_n=3&seed=7&tiles=$grid")
check "multipart upload gives the same answer" test \
  "$status/$(jq -c '[.candidates[].id]' "$B")" = "200/$(jq -c '[.candidates[].id]' "$TMP/first.json")"
# a time budget no tile fits in: the first tile, and the answer of its votes
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" \
  "$BASE/localize?top_n=3&seed=7&tiles=2x2%2B24&budget_ms=0.001")
check "budget_ms ends the search after its first tile, with an answer and the time it saved" test \
  "$status/$(jq -r '[.stop.kind, .tiles.extracted, .tiles.total, (.candidates | length > 0), (.tiles.saved_ms > 0)] | join(",")' "$B")" \
  = "200/budget,1,4,true,true"
status=$(req "$B" -H 'Content-Type: application/octet-stream' --data-binary @"$IMG" "$BASE/localize")
check "application/octet-stream is accepted" test "$status" = 200
s1=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize"; jq -r .seed "$B")
s2=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize"; jq -r .seed "$B")
check "without a seed each request draws its own" test "$s1" != "$s2"
# unverified: a verified search would vote the rest of the tile it stops in
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?rule=fixed&fraction=0.5&seed=1&verify=false")
check "rule fixed 0.5 uses half the features" jqt --arg s "$status" '
  $s == "200" and .rule.name == "fixed" and .rule.parameter == "fraction" and .rule.value == 0.5
  and .stop.kind == "rule" and .features.used == ((.features.total / 2) | ceil)' "$B"
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?rule=hoeffding&delta=0.1&min_score=1000")
check "min_score drops every candidate" test "$status/$(jq '.candidates | length' "$B")" = "200/0"
# min_distinct keeps, of the same answer, the candidates at least that
# distinct, ranked again from 1 (with and without verification; the grid
# named, so the learned plan cannot answer the two requests differently)
for v in false true; do
  req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?top_n=10&seed=7&verify=$v&tiles=2x2%2B24" >/dev/null
  cp "$B" "$TMP/all.json"
  cut=$(jq '[.candidates[].distinct] | sort | .[length / 2 | floor]' "$TMP/all.json")
  status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?top_n=10&seed=7&verify=$v&tiles=2x2%2B24&min_distinct=$cut")
  check "min_distinct=$cut (verify=$v) keeps the candidates that distinct, ranked from 1" test \
    "$status/$(jq -c '[.candidates[] | [.rank, .id]]' "$B")" = \
    "200/$(jq -c --argjson cut "$cut" '[.candidates[] | select(.distinct >= $cut)] | to_entries | map([.key + 1, .value.id])' "$TMP/all.json")"
done
check "min_distinct drops at least one candidate" test "$(jq '.candidates | length' "$B")" -lt "$(jq '.candidates | length' "$TMP/all.json")"

# Streaming extraction, the verified stop and the one rule parser.
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?rule=verified&inliers=12&seed=3")
check "rule verified answers with inlier counts ($(jq -c '{tiles, stop: .stop.detail}' "$B"))" jqt --arg s "$status" '
  $s == "200" and .rule.name == "verified" and .rule.parameter == "inliers"
  and (.candidates[0] | has("inliers") and has("verified"))
  and .tiles.extracted <= .tiles.total and .features.extracted >= .features.used' "$B"
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?rule=none&tiles=3x2%2B16&seed=3")
check "tiles=3x2+16: the full search extracts all 6 tiles" jqt --arg s "$status" '
  $s == "200" and .tiles == {"extracted": 6, "total": 6, "grid": "3x2+16", "order": "richest", "saved_ms": 0}
  and .features.extracted == .features.total and .features.used == .features.total' "$B"
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?rule=none&tiles=3x2+16&seed=3")
check "tiles=3x2+16 with its + unescaped (a space in a query string) names the same grid" jqt --arg s "$status" '
  $s == "200" and .tiles.grid == "3x2+16" and .tiles.total == 6' "$B"
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?rule=none&seed=3")
check "rule=none without tiles= extracts the image whole" jqt --arg s "$status" '
  $s == "200" and .tiles == {"extracted": 1, "total": 1, "grid": "1x1+0", "order": "richest", "saved_ms": 0}
  and .features.used == .features.total' "$B"
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?rule=none&tiles=2x2%2B24&tile_order=random&seed=3")
check "tile_order=random is reported and extracts every tile" jqt --arg s "$status" '
  $s == "200" and .tiles == {"extracted": 4, "total": 4, "grid": "2x2+24", "order": "random", "saved_ms": 0}' "$B"
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?rule=none&tiles=2x2%2B24&tile_order=spread&seed=3")
check "tile_order=spread is reported and extracts every tile" jqt --arg s "$status" '
  $s == "200" and .tiles == {"extracted": 4, "total": 4, "grid": "2x2+24", "order": "spread", "saved_ms": 0}' "$B"
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?rule=place-z&threshold=2&or_verified=12&seed=3")
check "or_verified=12 beside place-z is reported and verifies the answer ($(jq -c .stop.detail "$B"))" jqt --arg s "$status" '
  $s == "200" and .rule.name == "place-z" and .rule.or_verified == 12
  and (.candidates[0] | has("inliers") and has("verified"))
  and all(.candidates[]; if .verified == true then .scale > 0 else (has("scale") | not) end)' "$B"
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?seed=3")
check "the default rule has its verified stop of 12 inliers" jqt --arg s "$status" '
  $s == "200" and .rule == {"name": "place-z", "parameter": "threshold", "value": 2.25, "or_verified": 12}' "$B"
status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?rule=place-z&threshold=2&seed=3")
check "naming the rule and its parameter searches without the verified stop" jqt --arg s "$status" '
  $s == "200" and .rule.name == "place-z" and (.rule | has("or_verified") | not)' "$B"
for bad in "tiles=0x2" "tile_order=sideways" "rule=none&threshold=2" "rule=peak-mean&inliers=12" "rule=verified&inliers=3" \
  "rule=none&or_verified=12" "rule=verified&inliers=12&or_verified=12" "or_verified=3" "or_verified=0" "or_verified=abc"; do
  status=$(req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?$bad")
  check "$bad is 400 invalid_parameter ($(jq -r .error.message "$B"))" \
    test "$status/$(jq -r .error.code "$B")" = "400/invalid_parameter"
done

# A flat grey image has no SIFT features: a 200 answer with no candidates.
{ printf 'P5\n64 64\n255\n'; head -c 4096 /dev/zero | tr '\0' '\200'; } >"$TMP/flat.pgm"
status=$(req "$B" -H 'Content-Type: image/x-portable-graymap' --data-binary @"$TMP/flat.pgm" "$BASE/localize")
check "image without features is 200 with no candidates" jqt --arg s "$status" '
  $s == "200" and .candidates == [] and .features.total == 0 and .features.used == 0
  and .stop.kind == "exhausted"' "$B"

# Every query of the dataset against the map: is the top candidate correct?
correct=0
total=0
while read -r query; do
  [ -n "$query" ] || continue
  total=$((total + 1))
  req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$RTAB/$query" "$BASE/localize?top_n=1&seed=1" >/dev/null
  top=$(jq -r '.candidates[0].name // ""' "$B")
  grep -qxF "$query,$top" "$RTAB/ground_truth.csv" && correct=$((correct + 1))
done <"$RTAB/queries.txt"
echo "      top candidate correct for $correct of $total queries (floor $MIN_CORRECT)"
check "real queries localize ($correct of $total correct, floor $MIN_CORRECT)" test "$correct" -ge "$MIN_CORRECT"

# --- protobuf ----------------------------------------------------------------
ctype=$(curl -s -o "$TMP/answer.pb" -w '%{http_code} %{content_type}' -H 'Accept: application/x-protobuf' \
  -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/localize?seed=7")
check "Accept: application/x-protobuf answers protobuf" test "$ctype" = "200 application/x-protobuf"
check "protobuf body is not empty and holds the map name" grep -q rtabmap-loop "$TMP/answer.pb"

# --- request ids -------------------------------------------------------------
check "x-request-id is echoed" sh -c "curl -s -D - -o /dev/null -H 'x-request-id: suite-42' '$BASE/healthz' | grep -qi '^x-request-id: suite-42'"
check "x-request-id is generated when absent" sh -c "curl -s -D - -o /dev/null '$BASE/healthz' | grep -qiE '^x-request-id: [0-9a-f-]{36}'"
check "the request log line carries id, status, latency and fraction" \
  grep -qE 'request_id=suite-42 .*status=200 latency_ms=' "$TMP/server.log"
check "a localize log line carries the fraction used" grep -qE 'route="/localize" status=200 latency_ms=[0-9.]+ fraction_used=' "$TMP/server.log"

# --- error paths: status, code, and the server still answers ------------------
# expect NAME STATUS CODE CURL-ARGS...
expect() {
  local name=$1 want_status=$2 want_code=$3; shift 3
  local status code alive
  status=$(req "$B" "$@")
  code=$(jq -r '.error.code // empty' "$B" 2>/dev/null)
  alive=$(curl -s -o /dev/null -w '%{http_code}' "$BASE/healthz")
  if [ "$status/$code/$alive" = "$want_status/$want_code/200" ]; then
    ok "$name → $status $code"
  else
    fail "$name" "got $status/$code (server alive: $alive), want $want_status/$want_code; body: $(head -c 300 "$B")"
  fi
}
JPEG=(-H 'Content-Type: image/jpeg')
echo "not an image" >"$TMP/text.jpg"
head -c 300 "$IMG" >"$TMP/cut-in-header.jpg"
head -c 3000000 /dev/urandom >"$TMP/big.bin"
# A PNG header declaring 50000×50000 pixels (a decompression bomb's header).
printf '\x89PNG\r\n\x1a\n\x00\x00\x00\x0dIHDR\x00\x00\xc3\x50\x00\x00\xc3\x50\x08\x00\x00\x00\x00\x00\x00\x00\x00' >"$TMP/bomb.png"

expect "empty body" 400 empty_body "${JPEG[@]}" --data-binary '' "$BASE/localize"
expect "not an image" 422 undecodable_image "${JPEG[@]}" --data-binary @"$TMP/text.jpg" "$BASE/localize"
expect "JPEG cut inside its header" 422 undecodable_image "${JPEG[@]}" --data-binary @"$TMP/cut-in-header.jpg" "$BASE/localize"
expect "decompression bomb (50000x50000 PNG header)" 422 image_too_large -H 'Content-Type: image/png' --data-binary @"$TMP/bomb.png" "$BASE/localize"
expect "body over the limit" 413 body_too_large "${JPEG[@]}" --data-binary @"$TMP/big.bin" "$BASE/localize"
expect "multipart body over the limit" 413 body_too_large -F "image=@$TMP/big.bin" "$BASE/localize"
expect "wrong content type" 415 unsupported_media_type -H 'Content-Type: text/plain' --data-binary @"$IMG" "$BASE/localize"
expect "form-urlencoded (curl's default)" 415 unsupported_media_type --data-binary @"$IMG" "$BASE/localize"
expect "multipart without an image field" 400 missing_image_field -F "photo=@$IMG" "$BASE/localize"
expect "unknown rule" 400 unknown_rule "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?rule=fastest"
expect "top_n=0" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?top_n=0"
expect "budget_ms=0" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?budget_ms=0"
expect "budget_ms=-1" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?budget_ms=-1"
expect "top_n huge" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?top_n=99999999999999999999"
expect "threshold=NaN" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?rule=peak-mean&threshold=NaN"
expect "threshold=-1" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?rule=peak-mean&threshold=-1"
expect "min_distinct=2" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?min_distinct=2"
expect "threshold=abc" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?rule=peak-mean&threshold=abc"
expect "rule needing a parameter without one" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?rule=hoeffding"
expect "seed=abc" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?seed=abc"
expect "unknown query parameter" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?top_k=3"
expect "unknown route" 404 not_found "$BASE/nowhere"
expect "wrong method" 405 method_not_allowed "$BASE/localize"

# A JPEG cut after its header would decode (libjpeg fills the rest with
# grey) and answer from a fraction of the picture: it is refused as
# truncated instead, and a JPEG with bytes after its end is not.
head -c 10000 "$IMG" >"$TMP/cut-in-data.jpg"
expect "JPEG cut in its data" 422 undecodable_image "${JPEG[@]}" --data-binary @"$TMP/cut-in-data.jpg" "$BASE/localize"
check "JPEG cut in its data is named truncated" grep -q truncated "$B"
{ cat "$IMG"; printf 'trailing bytes'; } >"$TMP/trailer.jpg"
status=$(req "$B" "${JPEG[@]}" --data-binary @"$TMP/trailer.jpg" "$BASE/localize")
check "JPEG with bytes after its end is answered" test "$status/$(jq -r .image.width "$B")" = "200/512"

# --- unusual images (tests/fixtures, made by tests/fixtures/generate.py) ------
FIX="$ROOT/tests/fixtures"
OCTET=(-H 'Content-Type: application/octet-stream')
expect "animated GIF" 415 unsupported_image_format "${OCTET[@]}" --data-binary @"$FIX/animated.gif" "$BASE/localize"
expect "multipart with two image fields" 400 invalid_multipart -F "image=@$IMG" -F "image=@$IMG" "$BASE/localize"
expect "top_n=1000000000" 400 invalid_parameter "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?top_n=1000000000"
# expect_answer NAME FILE JQ-FILTER: 200, the filter holds, the server still answers
expect_answer() {
  local status alive
  status=$(req "$B" "${OCTET[@]}" --data-binary @"$2" "$BASE/localize?seed=1")
  alive=$(curl -s -o /dev/null -w '%{http_code}' "$BASE/healthz")
  if [ "$status/$alive" = 200/200 ] && jqt "$3" "$B"; then
    ok "$1 → 200 ($(jq -c '{features: .features.total, candidates: (.candidates | length)}' "$B"))"
  else
    fail "$1" "got $status (server alive: $alive); body: $(head -c 300 "$B")"
  fi
}
found='.features.total > 0 and (.candidates | length) > 0 and .image.width == 160'
expect_answer "16-bit grayscale PNG is read as 8-bit gray" "$FIX/gray16.png" "$found"
expect_answer "RGBA PNG is read as gray, alpha ignored" "$FIX/rgba.png" "$found"
expect_answer "CMYK JPEG is read as gray" "$FIX/cmyk.jpg" "$found"
none='.features.total == 0 and .candidates == [] and .stop.kind == "exhausted"'
expect_answer "1×1 PNG has no features" "$FIX/one-pixel.png" "$none and .image.width == 1"
expect_answer "uniform PNG has no features" "$FIX/uniform.png" "$none"
expect_answer "uniform JPEG has no features" "$FIX/uniform.jpg" "$none"

# --- the map's images: add, query, remove; the write token -------------------
# A server on a copy of the map, with a write token. An image from another
# dataset (gardens-point) is not in the map: its query does not answer it;
# once added it is the top candidate, also after a compaction and a restart;
# once removed it is gone again.
check "writes are 403 writes_disabled without a configured token" test \
  "$(req "$B" -X PUT -H 'Content-Type: image/jpeg' --data-binary @"$IMG" "$BASE/images/x")/$(jq -r .error.code "$B")" = "403/writes_disabled"
mkdir -p "$TMP/live"
cp "$TMP/map.bowmap" "$TMP/live/map.bowmap"
TOKEN=curl-suite-write-token-0123456789
sed "s|$TMP/map.bowmap|$TMP/live/map.bowmap|" "$TMP/config.toml" >"$TMP/live.toml"
printf '[auth]\nwrite_token = "%s"\n' "$TOKEN" >>"$TMP/live.toml"
NEW="$GARDENS/day_left/Image010.jpg"
AUTH=(-H "Authorization: Bearer $TOKEN")
top_name() { # top_name IMAGE: the name of the top candidate (or "none")
  req "$B" -H 'Content-Type: image/jpeg' --data-binary @"$1" "$LBASE/localize?rule=none&seed=1" >/dev/null
  jq -r '.candidates[0].name // "none"' "$B"
}
if start_server "$TMP/live.toml" "$TMP/live.log"; then
  LBASE=$BASE
  LPID=$PID
  check "a picture of another place is not answered with it before it is added" test "$(top_name "$NEW")" != "garden/10"
  check "PUT without a token is 401 unauthorized, with WWW-Authenticate" test \
    "$(curl -s -o "$B" -D "$TMP/h" -w '%{http_code}' -X PUT -H 'Content-Type: image/jpeg' --data-binary @"$NEW" "$LBASE/images/garden%2F10")/$(jq -r .error.code "$B")/$(grep -ci '^www-authenticate: bearer' "$TMP/h")" = "401/unauthorized/1"
  check "PUT with another token is 403 forbidden" test \
    "$(req "$B" -X PUT -H 'Authorization: Bearer not-the-token-at-all' -H 'Content-Type: image/jpeg' --data-binary @"$NEW" "$LBASE/images/garden%2F10")/$(jq -r .error.code "$B")" = "403/forbidden"
  check "nothing was added by the refused writes" test "$(req "$B" "$LBASE/images/garden%2F10")/$(jq -r .error.code "$B")" = "404/image_not_found"
  status=$(req "$B" -X PUT "${AUTH[@]}" -H 'Content-Type: image/jpeg' --data-binary @"$NEW" "$LBASE/images/garden%2F10?place=garden")
  check "PUT /images/{id} adds it: 201 with its features and generation 1" test \
    "$status/$(jq -r '.id, .generation, .replaced, (.features > 0)' "$B" | paste -sd/)" = "201/garden/10/1/false/true"
  check "a query then finds it first" test "$(top_name "$NEW")" = "garden/10"
  check "GET /images/{id} shows it with its place" test \
    "$(req "$B" "$LBASE/images/garden%2F10")/$(jq -r '.id, .place, .index, (.added_at_ms > 0)' "$B" | paste -sd/)" = "200/garden/10/garden/40/true"
  check "GET /images lists 41 images a page at a time" test \
    "$(req "$B" "$LBASE/images?offset=40&limit=5")/$(jq -r '.total, (.images | length), .images[0].id' "$B" | paste -sd/)" = "200/41/1/garden/10"
  check "GET /map counts the change" test \
    "$(req "$B" "$LBASE/map")/$(jq -r '.changes.generation, .changes.added, .changes.images, .changes.log_records, .identity.images' "$B" | paste -sd/)" = "200/1/1/41/1/41"
  status=$(req "$B" -X PUT "${AUTH[@]}" -F "image=@$NEW" "$LBASE/images/garden%2F10")
  check "PUT again (multipart) replaces it: 200, replaced" test "$status/$(jq -r '.replaced, .generation' "$B" | paste -sd/)" = "200/true/2"
  status=$(req "$B" -X PUT "${AUTH[@]}" -H 'Content-Type: image/png' --data-binary @"$ROOT/tests/fixtures/uniform.png" "$LBASE/images/flat")
  check "an image without features is added and flagged" test \
    "$status/$(jq -r '.features, (.warning | test("no features"))' "$B" | paste -sd/)" = "201/0/true"
  for bad in "bad%20id" "%2Fabsolute"; do
    check "PUT /images/$bad is 400 invalid_id" test \
      "$(req "$B" -X PUT "${AUTH[@]}" -H 'Content-Type: image/jpeg' --data-binary @"$NEW" "$LBASE/images/$bad")/$(jq -r .error.code "$B")" = "400/invalid_id"
  done
  check "PUT with an unknown parameter is 400" test \
    "$(req "$B" -X PUT "${AUTH[@]}" -H 'Content-Type: image/jpeg' --data-binary @"$NEW" "$LBASE/images/y?x=1")/$(jq -r .error.code "$B")" = "400/invalid_parameter"
  check "PUT of bytes that are no image is 422 and adds nothing" test \
    "$(req "$B" -X PUT "${AUTH[@]}" -H 'Content-Type: image/jpeg' --data-binary 'not an image' "$LBASE/images/junk")/$(jq -r .error.code "$B")/$(req "$B" "$LBASE/images/junk")" = "422/undecodable_image/404"
  head -c 2100000 /dev/zero >"$TMP/big.bin"
  check "PUT of a body over limits.body_bytes is 413" test \
    "$(req "$B" -X PUT "${AUTH[@]}" -H 'Content-Type: image/jpeg' --data-binary @"$TMP/big.bin" "$LBASE/images/big")/$(jq -r .error.code "$B")" = "413/body_too_large"
  check "DELETE of an unknown id is 404 image_not_found" test \
    "$(req "$B" -X DELETE "${AUTH[@]}" "$LBASE/images/nothing-here")/$(jq -r .error.code "$B")" = "404/image_not_found"
  check "DELETE without a token is 401" test "$(req "$B" -X DELETE "$LBASE/images/flat")" = 401
  status=$(req "$B" -X POST "${AUTH[@]}" "$LBASE/map/compact")
  COMPACTED_AT=$(jq -r .compaction.at_ms "$B")
  got="$status/$(jq -r '.compacted, .compaction.images' "$B" | paste -sd/)"
  got="$got/$(req "$TMP/m.json" "$LBASE/map")/$(jq -r '.changes.log_records, .changes.file_generation, .map.images' "$TMP/m.json" | paste -sd/)"
  check "POST /map/compact folds the log: 200, 42 images, log empty ($got)" test "$got" = "200/true/42/200/0/3/42"
  check "after the compaction the query still finds it" test "$(top_name "$NEW")" = "garden/10"
  kill -KILL "$LPID"; wait "$LPID" 2>/dev/null
  if start_server "$TMP/live.toml" "$TMP/live2.log"; then
    LBASE=$BASE
    LPID=$PID
    check "after SIGKILL and a restart the image is still there" test "$(top_name "$NEW")" = "garden/10"
    got="$(req "$TMP/m.json" "$LBASE/map")/$(jq -r '.changes.last_compaction | .at_ms, .images, .seconds' "$TMP/m.json" | paste -sd/)"
    check "/map reports the last compaction after a restart ($got)" test "$got" = "200/$COMPACTED_AT/42/null"
    status=$(req "$B" -X DELETE "${AUTH[@]}" "$LBASE/images/garden%2F10")
    check "DELETE /images/{id} is 200 with the next generation" test "$status/$(jq -r .generation "$B")" = "200/4"
    check "a query then no longer finds it" test "$(top_name "$NEW")" != "garden/10"
    check "GET /images/{id} of it is 404" test "$(req "$B" "$LBASE/images/garden%2F10")" = 404
    kill -KILL "$LPID"; wait "$LPID" 2>/dev/null
    if start_server "$TMP/live.toml" "$TMP/live3.log"; then
      got="$(req "$B" "$BASE/images/garden%2F10")/$(req "$TMP/m.json" "$BASE/map")/$(jq -r .changes.generation "$TMP/m.json")"
      check "the removal survives a restart (replayed from the change log; $got)" test "$got" = "404/200/4"
      kill -TERM "$PID"; wait "$PID" 2>/dev/null
    else
      fail "the live server restarts"
    fi
  else
    fail "the live server restarts after SIGKILL"
  fi
  check "no panic or error in the live server's logs" sh -c "! grep -hE 'panicked|ERROR' '$TMP'/live*.log"
else
  fail "a server with a write token starts"
fi
BASE=$MAIN_BASE
PID=$MAIN_PID

# --- metrics -----------------------------------------------------------------
metric() { # metric NAME{LABELS}: its value in a fresh scrape (0 if absent)
  curl -s "$BASE/metrics" | awk -v k="$1" '$1 == k { v = $2 } END { print v + 0 }'
}
ok200='bowloc_http_requests_total{route="/localize",method="POST",status="200"}'
total_count='bowloc_localize_duration_seconds_count'
extract_count='bowloc_localize_stage_duration_seconds_count{stage="extract"}'
unknown_rule='bowloc_http_errors_total{status="400",code="unknown_rule"}'
before=$(metric "$ok200"); stages_before=$(metric "$total_count"); extract_before=$(metric "$extract_count")
errors_before=$(metric "$unknown_rule")
rejections_before=$(curl -s "$BASE/metrics" | awk '/^bowloc_rejected_requests_total/ { n += $2 } END { print n + 0 }')
req "$B" "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize" >/dev/null
req "$B" "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?rule=fastest" >/dev/null
check "requests counter moves" test "$(metric "$ok200")" -eq $((before + 1))
check "localization latency histogram moves" test "$(metric "$total_count")" -eq $((stages_before + 1))
check "stage latency histogram moves" test "$(metric "$extract_count")" -eq $((extract_before + 1))
check "errors counter moves by status and code" test "$(metric "$unknown_rule")" -eq $((errors_before + 1))
rejections_after=$(curl -s "$BASE/metrics" | awk '/^bowloc_rejected_requests_total/ { n += $2 } END { print n + 0 }')
check "a 400 is not counted as a rejection ($rejections_before → $rejections_after)" \
  test "$rejections_after" = "$rejections_before"
curl -s "$BASE/metrics" >"$TMP/metrics.txt"
for name in bowloc_http_request_duration_seconds_bucket bowloc_localize_features_used_ratio_bucket \
  bowloc_localize_query_features_bucket bowloc_localize_tiles_extracted_ratio_bucket \
  bowloc_localize_extraction_saved_seconds_bucket bowloc_http_requests_in_flight bowloc_map_images \
  bowloc_map_words bowloc_workers_busy bowloc_queue_waiting bowloc_localize_stops_total \
  bowloc_localize_duration_seconds_bucket bowloc_http_connections_open; do
  check "metrics export $name" grep -q "^$name" "$TMP/metrics.txt"
done
check "no stage=\"total\" in the stage histogram" sh -c "! grep -q 'stage=\"total\"' '$TMP/metrics.txt'"
check "the old name ..._features_used_fraction is gone" sh -c "! grep -q 'features_used_fraction' '$TMP/metrics.txt'"
for series in 'bowloc_rejected_requests_total{reason="deadline_exceeded"}' \
  'bowloc_http_errors_total{status="408",code="body_timeout"}' \
  'bowloc_http_connection_errors_total{kind="malformed_request"}' \
  'bowloc_localize_stops_total{kind="deadline"}' 'bowloc_localize_stops_total{kind="budget"}'; do
  check "labelled counter exported before it moves: $series" grep -qF "$series " "$TMP/metrics.txt"
done
for name in process_resident_memory_bytes process_open_fds process_cpu_seconds_total; do
  check "process metric $name is exported and positive" \
    awk -v k="$name" '$1 == k && $2 > 0 { found = 1 } END { exit !found }' "$TMP/metrics.txt"
done
# a gauge underneath (whole-second counters otherwise), typed a counter
check "process_cpu_seconds_total is typed a counter" grep -qx '# TYPE process_cpu_seconds_total counter' "$TMP/metrics.txt"
check "metrics is Prometheus text" sh -c "curl -s -D - -o /dev/null '$BASE/metrics' | grep -qi '^content-type: text/plain; version=0.0.4'"
check "map gauge holds the map size" grep -qx 'bowloc_map_images 40' "$TMP/metrics.txt"
check "the learned plan's draws are counted, both plans (its trials alternate)" \
  awk '$1 ~ /^bowloc_extraction_plan_requests_total\{plan="(tiles|coarse)"\}$/ && $2 > 0 { n++ } END { exit n != 2 }' "$TMP/metrics.txt"
check "the learnt cost of a keypoint is exported, above 0 and under a millisecond" \
  awk '$1 == "bowloc_tile_keypoint_seconds" && $2 > 0 && $2 < 0.001 { found = 1 } END { exit !found }' "$TMP/metrics.txt"
check "what the first three tiles take is exported, above 0 and under a second" \
  awk '$1 == "bowloc_tile_first_tiles_seconds" && $2 > 0 && $2 < 1 { found = 1 } END { exit !found }' "$TMP/metrics.txt"

# --- graceful shutdown under load --------------------------------------------
# Six requests upload at 50 kB/s (about a second each), then compete for the
# two workers. SIGTERM arrives once all six are in flight (the gauge counts
# the scrape too): every one finishes with 200, a request sent after SIGTERM
# while the server drains is refused, and the exit status is 0.
BIG="$GARDENS/day_left/Image000.jpg"
[ -f "$BIG" ] || BIG="$IMG"
curls=()
for i in 1 2 3 4 5 6; do
  curl -s -o "$TMP/term$i.json" -w '%{http_code}' --limit-rate 50k "${JPEG[@]}" \
    --data-binary @"$BIG" "$BASE/localize?rule=none" >"$TMP/term$i.status" &
  curls+=($!)
done
all_in_flight=no
for i in $(seq 1 200); do
  if [ "$(metric bowloc_http_requests_in_flight)" -ge 7 ]; then all_in_flight=yes; break; fi
  sleep 0.01
done
kill -TERM "$PID"
sleep 0.2
draining=no; kill -0 "$PID" 2>/dev/null && draining=yes
: >"$B"
late=$(curl -s -o "$B" -w '%{http_code}' --max-time 5 "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize")
late_code=$(jq -r '.error.code // empty' "$B" 2>/dev/null)
wait "${curls[@]}"
statuses=$(for i in 1 2 3 4 5 6; do cat "$TMP/term$i.status"; echo; done | paste -sd,)
check "six requests in flight at SIGTERM all complete with 200 ($statuses)" \
  test "$all_in_flight/$statuses" = "yes/200,200,200,200,200,200"
check "a request after SIGTERM is refused while the server drains (got ${late}${late_code:+ $late_code})" \
  test "$draining" = yes -a \( "$late" = 000 -o "$late/$late_code" = 503/shutting_down \)
wait "$PID"
rc=$?
check "SIGTERM stops the server with exit status 0" test "$rc" = 0
check "shutdown is logged" grep -q 'stopped' "$TMP/server.log"
# the learned plan (search.tiles ending in ,auto) is kept beside the map and
# a restart goes on from it: its typical costs are exported before any query
PLAN="$TMP/map.bowmap.plan.json"
check "the learned plan is kept beside the map at shutdown" \
  jq -e '.version == 1 and .learned.requests > 0 and .learned.tiles.samples > 0 and .learned.coarse.samples > 0 and (.context.map | length) == 16' "$PLAN"
if start_server "$TMP/config.toml" "$TMP/resumed.log"; then
  check "a restart resumes the learned plan" grep -q 'learned plan resumed' "$TMP/resumed.log"
  check "GET /map says the plan was resumed, from the requests the file holds" test \
    "$(req "$B" "$BASE/map")/$(jq -r '.extraction_plan | .resumed_from == .requests and .requests > 0 and .file != null' "$B")/$(jq -r .learned.requests "$PLAN")" \
    = "200/true/$(jq -r .extraction_plan.resumed_from "$B")"
  curl -s "$BASE/metrics" >"$TMP/metrics.txt"
  check "its typical costs are exported before any query" \
    awk '$1 ~ /^bowloc_extraction_plan_typical_seconds\{plan="(tiles|coarse)"\}$/ && $2 > 0 { n++ } END { exit n != 2 }' "$TMP/metrics.txt"
  kill -TERM "$PID"; wait "$PID" 2>/dev/null
else
  fail "the server restarts on its kept plan"
fi

# --- a second server: max_features and overload -------------------------------
# It also keeps at most 50 features per query (limits.max_features); the
# first server found more in the same image.
write_config "$TMP/tight.toml" 1 0 10000 50
if start_server "$TMP/tight.toml" "$TMP/tight.log"; then
  ok "server with one worker and no queue starts"
  status=$(req "$B" "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?rule=none&tiles=1x1")
  check "limits.max_features caps the features of a query ($(jq .features.total "$TMP/first.json") → $(jq .features.total "$B"))" \
    jqt --slurpfile first "$TMP/first.json" '.features.total == 50 and $first[0].features.total > 50' "$B"
  status=$(req "$B" "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?rule=none&tiles=2x2")
  check "the cap is shared out over the tiles of streaming extraction ($(jq -c .tiles "$B"))" \
    jqt '.features.total <= 50 and .features.extracted == .features.total and .tiles.extracted == .tiles.total' "$B"
  # One worker, no queue: of requests sent at once, those beyond the first
  # running are refused with 503 and Retry-After, never queued.
  curls=()
  for i in 1 2 3 4 5 6; do
    curl -s -D "$TMP/h$i" -o "$TMP/b$i" -w '%{http_code}' "${JPEG[@]}" --data-binary @"$BIG" "$BASE/localize" >"$TMP/s$i" &
    curls+=($!)
  done
  wait "${curls[@]}"
  refused=0; answered=0; bad=0
  for i in 1 2 3 4 5 6; do
    case "$(cat "$TMP/s$i")" in
      200) answered=$((answered + 1)) ;;
      503) if [ "$(jq -r .error.code "$TMP/b$i")" = overloaded ] && grep -qi '^retry-after: 1' "$TMP/h$i"; then
             refused=$((refused + 1)); else bad=$((bad + 1)); fi ;;
      *) bad=$((bad + 1)) ;;
    esac
  done
  check "overload: $answered answered, $refused refused with 503 overloaded + Retry-After" \
    test "$answered" -ge 1 -a "$refused" -ge 1 -a "$bad" -eq 0
  BUSY_ADDRESS=${BASE#http://}
  sed "s|^listen = .*|listen = \"$BUSY_ADDRESS\"|" "$TMP/config.toml" >"$TMP/busy-port.toml"
  startup_fails "port in use" "server.listen $BUSY_ADDRESS: Address already in use" "$TMP/busy-port.toml"
  kill -TERM "$PID"; wait "$PID"
  check "second server exits 0" test $? = 0
else
  fail "server with one worker and no queue starts"
fi

# --- start-up faults: exit status non-zero, the message names the cause -------
# with_files NAME VOCAB MAP: a copy of config.toml using these files.
with_files() {
  sed -e "s|^vocabulary = .*|vocabulary = \"$2\"|" -e "s|^map = .*|map = \"$3\"|" \
    "$TMP/config.toml" >"$TMP/$1.toml"
}
V="$TMP/vocab.bowvoc"
M="$TMP/map.bowmap"
size=$(stat -c %s "$M")
head -c $((size / 2)) "$M" >"$TMP/truncated.bowmap"
# one bit flipped in the middle of the map (inside its postings)
cp "$M" "$TMP/flipped.bowmap"
byte=$(od -An -tu1 -j $((size / 2)) -N1 "$M" | tr -d ' ')
printf "\\$(printf '%03o' $((byte ^ 16)))" |
  dd of="$TMP/flipped.bowmap" bs=1 seek=$((size / 2)) conv=notrunc status=none
head -3 "$RTAB/map.txt" | sed "s|^|$RTAB/|" >"$TMP/few.txt"
"$BIN" --log warn vocab build --images "$TMP/few.txt" --words 20 --out "$TMP/other.bowvoc" 2>>"$TMP/build.log"
with_files missing-vocab "$TMP/missing.bowvoc" "$M"
with_files missing-map "$V" "$TMP/missing.bowmap"
with_files truncated "$V" "$TMP/truncated.bowmap"
with_files flipped "$V" "$TMP/flipped.bowmap"
with_files other-vocab "$TMP/other.bowvoc" "$M"
startup_fails "missing vocabulary" "missing.bowvoc is missing" "$TMP/missing-vocab.toml"
startup_fails "missing map" "missing.bowmap is missing" "$TMP/missing-map.toml"
startup_fails "truncated map" "truncated.bowmap: file is truncated" "$TMP/truncated.toml"
startup_fails "map with a flipped bit" "flipped.bowmap: checksum mismatch" "$TMP/flipped.toml"
startup_fails "map built with another vocabulary" "map.bowmap: map was built with vocabulary" "$TMP/other-vocab.toml"
printf '[search]\ntop_m = 3\n' >"$TMP/unknown-key.toml"
startup_fails "unknown config key" "top_m" "$TMP/unknown-key.toml"
{ cat "$TMP/config.toml"; printf '[search]\ntop_n = -5\n'; } >"$TMP/bad-value.toml"
startup_fails "bad config value" "search.top_n" "$TMP/bad-value.toml"
startup_fails "bad environment value" "limits.queue: invalid type: found string \"lots\", expected usize (environment variable BOWLOC_LIMITS__QUEUE)" \
  "$TMP/config.toml" BOWLOC_LIMITS__QUEUE=lots
startup_fails "rule misspelt in the environment" "(search.rule from environment variable BOWLOC_SEARCH__RULE)" \
  "$TMP/config.toml" BOWLOC_SEARCH__RULE=relativ
startup_fails "unknown section in the environment" "environment variable BOWLOC_SERVR__LISTEN" \
  "$TMP/config.toml" BOWLOC_SERVR__LISTEN=0.0.0.0:1
mkdir -p "$TMP/a-directory"
with_files dir-map "$V" "$TMP/a-directory"
startup_fails "a directory as the map" "a-directory: is a directory, not a map file" "$TMP/dir-map.toml"
startup_fails "a directory as the configuration" "a-directory: is a directory, not a configuration file" "$TMP/a-directory"
startup_fails "a configuration file that is not there" \
  "nothere.toml: configuration file not found in the working directory $(pwd)" nothere.toml

# No configuration file named, and none at config/default.toml (an installed
# binary, the container): the built-in defaults, then the environment.
mkdir -p "$TMP/elsewhere"
if BOWLOC_SERVER__LISTEN=127.0.0.1:0 BOWLOC_FILES__VOCABULARY="$V" BOWLOC_FILES__MAP="$M" \
  BOWLOC_BOOTSTRAP__ENABLED=false start_server "" "$TMP/elsewhere.log" "$TMP/elsewhere"; then
  check "without a configuration file it starts on the built-in defaults" \
    grep -q 'configuration: the built-in defaults (no config/default.toml in the working directory)' "$TMP/elsewhere.log"
  kill -TERM "$PID"; wait "$PID"
else
  fail "without a configuration file it starts on the built-in defaults"
fi

# --- connections: timeouts, cap, headers, seeds --------------------------------
# A server with 1 s header and body timeouts and at most 4 connections.
write_config "$TMP/conn.toml" 1 4 10000
sed -i '/^log_format/a max_connections = 4\nheader_timeout_ms = 1000\nbody_timeout_ms = 1000\ndrain_ms = 1000' "$TMP/conn.toml"
if start_server "$TMP/conn.toml" "$TMP/conn.log"; then
  ok "server with 1 s header and body timeouts and at most 4 connections starts"
  PORT=${BASE##*:}
  # raw PAYLOAD: send PAYLOAD (a printf format) on a new connection, keep what
  # comes back in $TMP/raw, print the seconds until the server closed it.
  raw() {
    local start end
    start=$(date +%s.%N)
    exec 7<>"/dev/tcp/127.0.0.1/$PORT"
    # shellcheck disable=SC2059
    [ -n "$1" ] && printf "$1" >&7
    timeout 10 cat <&7 >"$TMP/raw"
    end=$(date +%s.%N)
    exec 7<&- 7>&-
    awk -v a="$start" -v b="$end" 'BEGIN { printf "%.2f", b - a }'
  }
  # at_timeout SECONDS: closed between 0.8 s and 2.5 s (the timeout is 1 s)
  at_timeout() { awk -v x="$1" 'BEGIN { exit !(x >= 0.8 && x <= 2.5) }'; }
  closed_silently() { at_timeout "$1" && test ! -s "$TMP/raw"; }
  answered_408() {
    at_timeout "$1" && head -1 "$TMP/raw" | grep -q '^HTTP/1.1 408' && grep -q '"code":"body_timeout"' "$TMP/raw"
  }
  t=$(raw '')
  check "an idle connection is closed at the header timeout (${t} s, no answer)" closed_silently "$t"
  t=$(raw 'GET /healthz HTTP/1.1\r\nHost: x\r\nX-Half: ')
  check "a connection that stops inside its headers is closed at the header timeout (${t} s)" closed_silently "$t"
  t=$(raw 'POST /localize HTTP/1.1\r\nHost: x\r\nContent-Type: image/jpeg\r\nContent-Length: 1000\r\n\r\n')
  check "Content-Length: 1000 and no body → 408 body_timeout, closed (${t} s: $(head -1 "$TMP/raw" | tr -d '\r'))" \
    answered_408 "$t"
  # HTTP/2 without TLS on the same port (server.http2, on by default), told
  # from HTTP/1.1 by the first bytes.
  status=$(curl -s --http2-prior-knowledge -o "$B" -w '%{http_version} %{http_code}' \
    "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?top_n=3")
  h2_answered() { test "$status" = "2 200" && jq -e '.candidates | length > 0' "$B" >/dev/null; }
  check "HTTP/2 with prior knowledge: /localize answered (version, status: $status)" h2_answered
  status=$(curl -s --http2 -o /dev/null -w '%{http_version} %{http_code}' "$BASE/healthz")
  check "a request asking to upgrade to h2c is answered in HTTP/1.1 ($status)" test "$status" = "1.1 200"
  # frames FILE: the types of the HTTP/2 frames in FILE (9-byte headers:
  # length, type, flags, stream)
  frames() {
    od -An -tu1 -v "$1" | tr -s ' \n' '\n' | grep . | awk '{ b[NR - 1] = $1 + 0 }
      END { for (i = 0; i + 9 <= NR; i += 9 + b[i] * 65536 + b[i + 1] * 256 + b[i + 2]) printf "%s%d", (i ? " " : ""), b[i + 3] }'
  }
  # the preface and an empty SETTINGS frame, then silence: GOAWAY (type 7)
  # after the 1 s header timeout, and as this client acknowledges nothing,
  # closed a timeout later
  t=$(raw 'PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n\x00\x00\x00\x04\x00\x00\x00\x00\x00')
  goaway_when_idle() { awk -v x="$t" 'BEGIN { exit !(x >= 1.8 && x <= 3.5) }' && frames "$TMP/raw" | grep -qw 7; }
  check "an idle HTTP/2 connection is sent GOAWAY and closed (${t} s; frame types $(frames "$TMP/raw"))" goaway_when_idle
  t=$(raw 'PRI * HTTP/2.0\r\n')
  check "a connection that stops inside HTTP/2's preface is closed at the header timeout (${t} s)" closed_silently "$t"

  # The cap: four idle connections hold every place; a fifth waits (curl
  # gives up after 0.5 s) until the idle ones time out.
  exec 3<>"/dev/tcp/127.0.0.1/$PORT" 4<>"/dev/tcp/127.0.0.1/$PORT" 5<>"/dev/tcp/127.0.0.1/$PORT" 6<>"/dev/tcp/127.0.0.1/$PORT"
  sleep 0.2
  capped=$(curl -s -o /dev/null -w '%{http_code}' --max-time 0.5 "$BASE/healthz")
  sleep 1.5
  freed=$(curl -s -o /dev/null -w '%{http_code}' --max-time 5 "$BASE/healthz")
  exec 3<&- 4<&- 5<&- 6<&-
  check "with 4 connections open a 5th waits (got $capped) and is served once they close (got $freed)" \
    test "$capped/$freed" = "000/200"

  # Header limits (limits.headers = 100, limits.header_bytes = 64 KiB): over
  # them a JSON 431; over four times them, hyper's own empty 431, counted.
  too_large='bowloc_http_connection_errors_total{kind="headers_too_large"}'
  malformed='bowloc_http_connection_errors_total{kind="malformed_request"}'
  many=(); for i in $(seq 1 150); do many+=(-H "X-Pad-$i: x"); done
  expect "150 header fields" 431 headers_too_large "${many[@]}" "$BASE/healthz"
  pad=$(head -c 50000 /dev/zero | tr '\0' a)
  expect "100 kB of header fields" 431 headers_too_large -H "X-A: $pad" -H "X-B: $pad" "$BASE/healthz"
  before=$(metric "$too_large")
  lots=(); for i in $(seq 1 500); do lots+=(-H "X-Pad-$i: x"); done
  status=$(req "$B" "${lots[@]}" "$BASE/healthz")
  check "500 header fields → bare 431 from the HTTP layer ($(stat -c %s "$B") bytes), counted" \
    test "$status/$(stat -c %s "$B")/$(metric "$too_large")" = "431/0/$((before + 1))"
  status=$(req "$B" -H "X-A: $pad" -H "X-B: $pad" -H "X-C: $pad" -H "X-D: $pad" -H "X-E: $pad" -H "X-F: $pad" "$BASE/healthz")
  check "300 kB of header fields → bare 431 from the HTTP layer, counted" \
    test "$status/$(metric "$too_large")" = "431/$((before + 2))"
  before=$(metric "$malformed")
  raw 'GARBAGE\r\n\r\n' >/dev/null
  check "a malformed request line → bare 400 from the HTTP layer ($(head -1 "$TMP/raw" | tr -d '\r')), counted" \
    test "$(head -1 "$TMP/raw" | cut -d' ' -f2)/$(metric "$malformed")" = "400/$((before + 1))"
  check "the HTTP layer's answers are logged" grep -q 'answered 400 by the HTTP layer' "$TMP/conn.log"

  # Seeds drawn by the server survive a JSON number (below 2^53); any u64
  # given is taken and reported as given.
  seeds=()
  for i in 1 2 3 4 5 6 7 8; do
    req "$B" "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?rule=none" >/dev/null
    seeds+=("$(grep -o '"seed":[0-9]*' "$B" | cut -d: -f2)")
  done
  safe=yes
  for seed in "${seeds[@]}"; do
    { [ -n "$seed" ] && [ "${#seed}" -le 16 ] && [ "$seed" -le 9007199254740991 ]; } || safe=no
  done
  check "drawn seeds are below 2^53 (${seeds[*]})" test "$safe" = yes
  status=$(req "$B" "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?seed=9223372036854775807")
  given_seed() { test "$status" = 200 && grep -q '"seed":9223372036854775807' "$B"; }
  check "seed 2^63-1 (the API's int64 maximum) is taken and reported as given" given_seed
  status=$(req "$B" "${JPEG[@]}" --data-binary @"$IMG" "$BASE/localize?seed=9223372036854775808")
  check "seed 2^63 is 400 invalid_parameter" test "$status/$(jq -r .error.code "$B")" = "400/invalid_parameter"

  # server.drain_ms = 1000: SIGTERM during an upload that sends 10 bytes
  # every 0.2 s (never pausing for the 1 s body timeout) for 4 s; the
  # process gives it 1 s, then exits 0 anyway, saying so.
  {
    printf 'POST /localize HTTP/1.1\r\nHost: x\r\nContent-Type: image/jpeg\r\nContent-Length: 100000\r\n\r\n'
    for i in $(seq 1 20); do printf 'xxxxxxxxxx'; sleep 0.2; done
  } 2>/dev/null >"/dev/tcp/127.0.0.1/$PORT" &
  slow=$!
  sleep 0.5
  start=$(date +%s.%N)
  kill -TERM "$PID"; wait "$PID"
  rc=$?
  t=$(awk -v a="$start" -v b="$(date +%s.%N)" 'BEGIN { printf "%.2f", b - a }')
  kill "$slow" 2>/dev/null; wait "$slow" 2>/dev/null
  drained() {
    test "$rc" = 0 && awk -v x="$t" 'BEGIN { exit !(x >= 0.9 && x <= 3) }' \
      && grep -q 'connections still open 1000 ms after shutdown began' "$TMP/conn.log"
  }
  check "SIGTERM with a request still uploading: exit $rc after ${t} s (server.drain_ms = 1000)" drained
else
  fail "server with 1 s header and body timeouts and at most 4 connections starts"
fi

# --- deadlines: no work for a request whose deadline has passed ----------------
# deadline_ms = 30: a slow upload is cut off at the deadline with 408; a
# request whose deadline passes before its search votes (here: while the
# whole image is extracted, tiles=1x1) is 503 deadline_exceeded and adds
# nothing to the features-used histogram.
write_config "$TMP/deadline.toml" 1 4 30
if start_server "$TMP/deadline.toml" "$TMP/deadline.log"; then
  ok "server with a 30 ms deadline starts"
  ratio_count=bowloc_localize_features_used_ratio_count
  before=$(metric "$ratio_count")
  # (no `Expect: 100-continue`: curl would wait up to 1 s before sending)
  answer=$(curl -s -o "$B" -w '%{http_code} %{time_total}' --limit-rate 4k -H 'Expect:' "${JPEG[@]}" \
    --data-binary @"$IMG" "$BASE/localize")
  # curl sends in bursts a second apart and reads the answer after a burst;
  # the server's log says when it answered.
  latency=$(grep -o 'status=408 latency_ms=[0-9.]*' "$TMP/deadline.log" | head -1 | cut -d= -f3)
  cut_off() {
    test "${1%% *}" = 408 && grep -q '"code":"request_timeout"' "$B" \
      && awk -v t="${latency:-9999}" 'BEGIN { exit !(t >= 30 && t < 500) }'
  }
  check "a body still arriving at the deadline → 408 request_timeout after ${latency:-?} ms (curl: $answer s; the upload takes 3.5 s)" \
    cut_off "$answer"
  results=()
  for i in 1 2 3 4 5 6; do
    status=$(req "$B" "${JPEG[@]}" --data-binary @"$BIG" "$BASE/localize?rule=none&tiles=1x1")
    results+=("$status/$(jq -r '.error.code // (.stop.kind + "/used=" + (.features.used | tostring))' "$B")")
  done
  answered=$(printf '%s\n' "${results[@]}" | grep -c '^200/')
  bad=$(printf '%s\n' "${results[@]}" | grep -vcE '^503/deadline_exceeded$|^200/(rule|exhausted|deadline)/used=[1-9]')
  exceeded=$(printf '%s\n' "${results[@]}" | grep -c '^503/deadline_exceeded$')
  check "past the deadline before any vote: 503 deadline_exceeded, never 200 with 0 features (${results[*]})" \
    test "$bad" = 0 -a "$exceeded" -ge 1
  check "only answered searches enter the features-used histogram (+$(($(metric "$ratio_count") - before)), answered $answered)" \
    test "$(metric "$ratio_count")" = "$((before + answered))"
  check "deadline refusals are counted as rejections" \
    test "$(metric 'bowloc_rejected_requests_total{reason="deadline_exceeded"}')" = "$exceeded"
  kill -TERM "$PID"; wait "$PID"
else
  fail "server with a 30 ms deadline starts"
fi

# --- bootstrap: only the default files, its progress on /readyz ----------------
# In an empty folder the default files (data/default/…) are missing; bootstrap
# builds them from rtabmap-loop with 200 words, and the map's ORB side. A mistyped --map is never
# built: serve exits naming it.
mkdir -p "$TMP/boot"
cat >"$TMP/boot/config.toml" <<TOML
[server]
listen = "127.0.0.1:0"
workers = 1
[bootstrap]
dataset = "$RTAB"
words = 200
TOML
cd "$TMP/boot" || exit 1
startup_fails "--map naming a missing file (bootstrap on)" "a/typo.bowmap are missing (bootstrap builds only the default files" \
  config.toml -- --map a/typo.bowmap
check "the mistyped map was not built" test ! -e "$TMP/boot/a"
cd "$ROOT" || exit 1
if launch config.toml "$TMP/boot.log" "$TMP/boot"; then
  steps=()
  last=""
  ready=no
  for i in $(seq 1 1200); do
    status=$(req "$B" "$BASE/readyz")
    [ "$status" = 200 ] && { ready=yes; break; }
    step=$(jq -r '.error.step // empty' "$B" 2>/dev/null)
    [ -n "$step" ] && [ "$step" != "${last:-}" ] && { steps+=("$step"); last=$step; }
    kill -0 "$PID" 2>/dev/null || break
    sleep 0.05
  done
  printf '      /readyz step: %s\n' "${steps[@]}"
  seen=$(printf '%s\n' "${steps[@]}")
  reported() {
    test "$ready" = yes && grep -q 'extracting the features of 40 images' <<<"$seen" \
      && grep -qE '^(k-means\+\+ seeding|Lloyd iterations) [0-9]+/[0-9]+$' <<<"$seen"
  }
  check "bootstrap reports its steps on /readyz, then is ready (${#steps[@]} steps seen)" reported
  check "bootstrap built the default files" test -f "$TMP/boot/data/default/vocab.bowvoc" -a -f "$TMP/boot/data/default/map.bowmap"
  check "bootstrap built the default map's ORB side (the pass is on by default)" test -f "$TMP/boot/data/default/map.orbpass"
  kill -TERM "$PID"; wait "$PID"
else
  fail "bootstrap server starts"
fi

# --- a JSON log: every line parses, the decoders' messages included ----------
# libpng writes its complaint about a damaged PNG to stderr itself; with
# log_format = "json" the server logs it as an event (target `native`),
# tied to the request whose job was running.
write_config "$TMP/json.toml" 1 4 10000
sed -i 's/^log_format = "human"/log_format = "json"/' "$TMP/json.toml"
if start_server "$TMP/json.toml" "$TMP/json.log"; then
  ok "server with a JSON log starts"
  head -c 1000 "$ROOT/tests/fixtures/rgba.png" >"$TMP/cut.png"
  expect "PNG cut short, JSON log" 422 undecodable_image -H 'Content-Type: image/png' \
    -H 'x-request-id: cut-png-7' --data-binary @"$TMP/cut.png" "$BASE/localize"
  kill -TERM "$PID"; wait "$PID"
  every_line_parses() { jq -e . "$1" >/dev/null 2>&1; }
  native_libpng() { jq -s -e 'any(.[]; .target == "native" and .level == "WARN" and (.message | startswith("libpng")))' "$1" >/dev/null; }
  check "every line of the JSON log parses ($(wc -l <"$TMP/json.log") lines)" every_line_parses "$TMP/json.log"
  check "libpng's own message is in it as a warning, target native ($(jq -r 'select(.target == "native") | .message' "$TMP/json.log" | head -1))" \
    native_libpng "$TMP/json.log"
  native_request() { jq -s -e 'any(.[]; .target == "native" and (.message | startswith("libpng")) and .request_id == "cut-png-7")' "$1" >/dev/null; }
  check "libpng's message names the request that caused it (request_id cut-png-7)" native_request "$TMP/json.log"
else
  fail "server with a JSON log starts"
fi

# --- the container's runtime libraries ---------------------------------------
if command -v dpkg >/dev/null && command -v ldd >/dev/null; then
  check "Dockerfile runtime packages provide every library the binary links" \
    bash "$ROOT/scripts/check-docker-runtime.sh" "$BIN"
fi

finish
