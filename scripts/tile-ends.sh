#!/usr/bin/env bash
# What a stopping rule that decides at tile ends can reach: runs
# examples/tile_ends.rs (every query's state after each of its 2x2+24 tiles:
# top-1 and top-5 right or not, place-z's statistic, decode and extraction
# time so far against the whole image's) for vocabulary seeds 1 to 3 on both
# shared datasets, then prints the median time share spent by each tile end
# and, for stops at tile ends only, the worst seed's loss of recall@1 /
# recall@5 against the full search and the median and mean time share:
#   - place-z thresholds z;
#   - a "predictive" z, z·√(t/R) (t features voted, R left): how many spreads
#     the lead is of what the features left could still move it;
#   - the best per-tile-end thresholds of a grid, chosen in hindsight on
#     gardens-point (an upper bound for any z schedule), and the same on
#     rtabmap-loop; with verification also chosen on two vocabulary seeds
#     and tried on the third;
#   - the oracle that stops at the first tile end whose answer is as good as
#     the full search's (a bound for any rule);
#   - z with a geometric check: stop also at a lower z when the leader's
#     place (the map images within 2 of it) has m inliers against the
#     features voted so far;
#   - how often the answer after two tiles is worse than the full search's,
#     and how well z and other statistics rank those cases (AUC);
#   - the same with verification on (the service's default): each tile
#     end's answer re-ranked by inliers against the features so far, the loss
#     taken against the verified full search, and a stop that also fires when
#     the answer has m inliers showing the scene at the query's scale;
#   - all the statistics at once: a logistic regression fitted to say
#     whether a tile end's answer is as good as the verified full search's,
#     cross-validated over the vocabulary seeds of gardens-point, fitted on
#     it and tried on rtabmap-loop, and in hindsight.
#
#   scripts/tile-ends.sh [OUT]     (default OUT: data/eval/tile-ends)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-data/eval/tile-ends}
mkdir -p "$out"
cargo build --release --quiet --example tile_ends
for seed in 1 2 3; do
  ./target/release/examples/tile_ends ../shared/datasets/gardens-point 5000 $seed >"$out/gardens-point-$seed.csv" 2>/dev/null
  ./target/release/examples/tile_ends ../shared/datasets/rtabmap-loop 1000 $seed >"$out/rtabmap-loop-$seed.csv" 2>/dev/null
done
python3 - "$out" <<'PY'
import bisect, collections, csv, itertools, math, statistics, sys

out = sys.argv[1]

def load(name):
    rows = collections.defaultdict(list)
    for seed in (1, 2, 3):
        for r in csv.DictReader(open(f"{out}/{name}-{seed}.csv")):
            rows[(r["seed"], r["run"], r["query"])].append({k: float(v) for k, v in r.items()})
    return rows

def evaluate(rows, stop, top1="top1", top5="top5"):
    per_seed = collections.defaultdict(lambda: [0, 0, 0, 0, 0])
    times = []
    for key, ends in rows.items():
        k = next((i for i in range(len(ends) - 1) if stop(ends, i)), len(ends) - 1)
        e, f = ends[k], ends[-1]
        d = per_seed[key[0]]
        d[0] += f[top1]; d[1] += e[top1]; d[2] += f[top5]; d[3] += e[top5]; d[4] += 1
        times.append(e["time_share"])
    loss = max(max(d[0] - d[1], d[2] - d[3]) * 100 / d[4] for d in per_seed.values())
    return loss, statistics.median(times), statistics.mean(times)

def show(label, a, b):
    print(f"{label:34} gardens-point: loss {a[0]:4.1f}, time {a[1]:.3f} / {a[2]:.3f} | "
          f"rtabmap-loop: loss {b[0]:4.1f}, time {b[1]:.3f} / {b[2]:.3f}")

gp, rt = load("gardens-point"), load("rtabmap-loop")
both = lambda stop, *keys: (evaluate(gp, stop, *keys), evaluate(rt, stop, *keys))
print("stops at tile ends only; loss: worst seed, points of recall@1 or recall@5; "
      "time: median / mean share of the whole image's decode + extraction")
show("full search (all four tiles)", *both(lambda e, i: False))
for name, rows in (("gardens-point", gp), ("rtabmap-loop", rt)):
    spent = [statistics.median(ends[i]["time_share"] for ends in rows.values() if len(ends) > i)
             for i in range(4)]
    print(f"  {name}: median time share spent by the end of tile 1, 2, 3, 4: "
          + ", ".join(f"{t:.3f}" for t in spent))
for z in (1, 1.5, 2, 2.5, 3):
    show(f"place-z {z}", *both(lambda e, i, z=z: e[i]["z"] > z))
def predictive(e, i):
    s = e[i]["features"] / max(e[i]["total"], 1)
    return e[i]["z"] * math.sqrt(s / (1 - s)) if s < 1 else math.inf
for z in (1.5, 2, 3, 3.5, 4):
    show(f"predictive z {z}", *both(lambda e, i, z=z: predictive(e, i) > z))
grid = [1, 1.25, 1.5, 1.75, 2, 2.5, 3, 4, math.inf]
def best_schedule(rows, *keys):
    """The z thresholds after tiles 1, 2, 3 (of the grid) with the lowest
    median time share that lose at most a point on `rows`."""
    schedules = ((evaluate(rows, lambda e, i, t=t: e[i]["z"] > t[i], *keys), t)
                 for t in itertools.product(grid, repeat=3))
    return min((median, t) for (loss, median, _), t in schedules if loss <= 1.0)[1]
best = best_schedule(gp)
show(f"best z per tile end {best}", *both(lambda e, i: e[i]["z"] > best[i]))
for m in (12, 24, 48):
    show(f"z > 1 with {m} place inliers, or z > 2",
         *both(lambda e, i, m=m: (e[i]["z"] > 1 and e[i]["place_inliers"] >= m) or e[i]["z"] > 2))
def as_good(ends, i, top1="top1", top5="top5"):
    """Whether the answer at tile end i is as good as the full search's (the last end's)."""
    return ends[i][top1] >= ends[-1][top1] and ends[i][top5] >= ends[-1][top5]
show("oracle", *both(as_good))
def auc(good, bad):
    """How often a search that answers as well as the full search scores above one that does not."""
    good = sorted(good)
    below = sum(bisect.bisect_left(good, v) + 0.5 * (bisect.bisect_right(good, v) - bisect.bisect_left(good, v))
                for v in bad)
    return 1 - below / len(bad) / len(good)
statistics_at_two = {
    "z": lambda e, p: e["z"],
    "the tile's own votes lead in the same place": lambda e, p: e["tile_agrees"],
    "z of the tile's votes alone": lambda e, p: e["tile_leader_z"],
    "the leader kept its place from the tile before": lambda e, p: float(abs(e["leader"] - p["leader"]) <= 2),
    "z's growth from the tile before": lambda e, p: e["z"] - p["z"],
    "the leader's inliers": lambda e, p: e["leader_inliers"],
    "its place's inliers": lambda e, p: e["place_inliers"],
}
def separation(statistics, top1="top1", top5="top5", label="the full search"):
    is_worse = lambda ends: not as_good(ends, 1, top1, top5)
    worse = [ends for ends in gp.values() if is_worse(ends)]
    print(f"gardens-point after two tiles: {len(worse)} of {len(gp)} searches answer worse than {label}; "
          "AUC of each statistic against them:")
    for name, f in statistics.items():
        good = [f(ends[1], ends[0]) for ends in gp.values() if not is_worse(ends)]
        bad = [f(ends[1], ends[0]) for ends in worse]
        print(f"  {name}: {auc(good, bad):.3f}")
separation(statistics_at_two)

# The same with verification on (the service's default): each tile end's
# answer is the top k re-ranked in the configured order, and the loss is
# against the verified full search.
verified = ("vtop1", "vtop5")
print("with verification: the answer at a tile end and the full search's both re-ranked by inliers")
show("full search, verified", *both(lambda e, i: False, *verified))
for z in (1, 1.5, 2, 2.5):
    show(f"place-z {z}, verified", *both(lambda e, i, z=z: e[i]["z"] > z, *verified))
at_scale = lambda e, m, s: e["v_inliers"] >= m and 0 <= e["v_log_scale"] <= s
for m, s in ((12, 0.1), (12, 0.2), (12, 0.4), (24, 0.2)):
    show(f"z > 2, or {m} inliers at |ln scale| <= {s}",
         *both(lambda e, i, m=m, s=s: e[i]["z"] > 2 or at_scale(e[i], m, s), *verified))
show("z > 2, or 12 inliers at any scale",
     *both(lambda e, i: e[i]["z"] > 2 or e[i]["v_inliers"] >= 12, *verified))
best = best_schedule(gp, *verified)
show(f"best z per tile end {best}", *both(lambda e, i: e[i]["z"] > best[i], *verified))
# The same schedule chosen on two vocabulary seeds, tried on the third.
for held in ("1", "2", "3"):
    t = best_schedule({k: v for k, v in gp.items() if k[0] != held}, *verified)
    tried = evaluate({k: v for k, v in gp.items() if k[0] == held},
                     lambda e, i: e[i]["z"] > t[i], *verified)
    print(f"  chosen on the other seeds {t}, tried on gardens-point seed {held}: "
          f"loss {tried[0]:4.1f}, time {tried[1]:.3f} / {tried[2]:.3f}")
show("oracle, verified", *both(lambda e, i: as_good(e, i, *verified), *verified))
separation({
    "z": lambda e, p: e["z"],
    "the answer's inliers": lambda e, p: e["v_inliers"],
    "its inliers when its scale is within 0.2 of the query's": lambda e, p: e["v_inliers"] * at_scale(e, 0, 0.2),
    "its place's inliers": lambda e, p: e["place_inliers"],
}, *verified, label="the verified full search")

# All the statistics at once: a logistic regression over them (and the tile
# end), fitted to say whether a tile end's answer is as good as the verified
# full search's; the search stops at the first tile end whose fitted score
# passes a threshold. Cross-validated on gardens-point (fitted and its
# threshold chosen on two vocabulary seeds, tried on the third), then fitted
# on all of gardens-point and tried on rtabmap-loop, and in hindsight (fitted
# and tried on all of gardens-point), an upper bound for this family.
def features(ends, i):
    e, p = ends[i], ends[i - 1] if i else None
    scaled = float(at_scale(e, 0, 0.2))
    return [1.0, e["z"], min(e["z"], 6.0) ** 2 / 6, math.log1p(e["leader_inliers"]),
            math.log1p(e["place_inliers"]), math.log1p(e["v_inliers"]),
            math.log1p(e["v_inliers"] * scaled), scaled, e["tile_agrees"], e["tile_leader_z"],
            float(p is not None and abs(p["leader"] - e["leader"]) <= 2),
            e["z"] - p["z"] if p else 0.0, math.log1p(e["features"]), float(i == 0), float(i == 1)]
def fit(rows, l2=1e-3, steps=400, rate=0.5):
    X = [features(ends, i) for ends in rows.values() for i in range(len(ends) - 1)]
    y = [float(as_good(ends, i, *verified)) for ends in rows.values() for i in range(len(ends) - 1)]
    mu = [statistics.mean(c) for c in zip(*X)]
    sd = [statistics.pstdev(c) or 1.0 for c in zip(*X)]
    mu[0], sd[0] = 0.0, 1.0
    Z = [[(v - m) / s for v, m, s in zip(x, mu, sd)] for x in X]
    w = [0.0] * len(mu)
    for _ in range(steps):
        g = [0.0] * len(w)
        for z, t in zip(Z, y):
            d = 1 / (1 + math.exp(-max(-30.0, min(30.0, sum(a * b for a, b in zip(w, z)))))) - t
            for j, v in enumerate(z):
                g[j] += d * v
        w = [a - rate * (b / len(Z) + l2 * a) for a, b in zip(w, g)]
    scored = {}  # by the row list's identity: each tile end is scored once
    def score(ends, i):
        if id(ends) not in scored:
            scored[id(ends)] = [sum(a * (v - m) / s for a, v, m, s in zip(w, features(ends, k), mu, sd))
                                for k in range(len(ends))]
        return scored[id(ends)][i]
    return score
seeds = lambda rows, keep: {k: v for k, v in rows.items() if k[0] in keep}
thresholds = [t / 4 for t in range(0, 41)]
def first_within_a_point(rows, score):
    return next(t for t in thresholds
                if evaluate(rows, lambda e, i: score(e, i) > t, *verified)[0] <= 1.0)
print("all the statistics at once (a logistic regression; a stop when its score passes a threshold), verified:")
for held in ("1", "2", "3"):
    train, test = seeds(gp, {"1", "2", "3"} - {held}), seeds(gp, {held})
    score = fit(train)
    t = first_within_a_point(train, score)
    tried = evaluate(test, lambda e, i: score(e, i) > t, *verified)
    good = [score(e, 1) for e in test.values() if as_good(e, 1, *verified)]
    bad = [score(e, 1) for e in test.values() if not as_good(e, 1, *verified)]
    print(f"  fitted on the other seeds, threshold {t:.2f}, tried on gardens-point seed {held}: loss {tried[0]:4.1f}, "
          f"time {tried[1]:.3f} / {tried[2]:.3f}; AUC after two tiles {auc(good, bad):.3f}")
score = fit(gp)
t = first_within_a_point(gp, score)
show(f"  fitted on gardens-point, {t:.2f}", *both(lambda e, i: score(e, i) > t, *verified))
for t in (1.0, 1.5, 2.0, 2.5, 3.0):
    show(f"  in hindsight, threshold {t:.2f}", *both(lambda e, i, t=t: score(e, i) > t, *verified))
PY
