#!/usr/bin/env bash
# What each order of the verified candidates gives, without a new search:
# runs examples/candidates.rs (every query's top 10 vote candidates of the
# full search, verified) for vocabulary seeds 1 to 3, then prints recall@1 per
# seed when the top candidate is taken
#   - by votes (no verification),
#   - by its own inliers (verify.order = "inliers"),
#   - by the inliers of its place, equal sums in vote order,
#   - by the inliers of its place, equal sums by its own inliers, then in
#     vote order (verify.order = "place"),
#   - the place as verify.order = "place" picks it, answered by the checked
#     candidate of that place nearest its inlier-weighted centre (not kept),
#   - the same place answered by its verified candidate whose inliers show
#     the scene at the scale nearest the query's (verify.order = "place-scale"),
#     and by any of its candidates with inliers (not kept);
# then, for "place" and "place-scale", how far the wrong answers are from the
# nearest right map image (in map images, along the map's order), and the
# median relative scale verified candidates show by where they were taken
# (map images from the middle of the query's right ones; edges clamped at ±5).
# A query without features counts as a miss.
#
#   scripts/verify-orders.sh [NAME:WORDS[:GRID] ...]
#     (default: gardens-point:5000 gardens-point:5000:2x2+24 rtabmap-loop:1000:2x2+24;
#      GRID as for `bowloc eval --tiles`, default whole queries)
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/candidates.sh
out=${OUT:-data/eval/verify-orders}
sets=("$@")
[ ${#sets[@]} -gt 0 ] || sets=(gardens-point:5000 gardens-point:5000:2x2+24 rtabmap-loop:1000:2x2+24)
for set in "${sets[@]}"; do
  candidate_csvs "$out" "$set"
  python3 - "$out" "$STEM" "$set" <<'PY'
import collections, csv, math, statistics, sys

out, stem, label = sys.argv[1:]
WINDOW = 2  # search.place_window
root = f"../shared/datasets/{label.split(':')[0]}"
lines = lambda f: [l.strip() for l in open(f"{root}/{f}") if l.strip()]
map_id = {path: i for i, path in enumerate(lines("map.txt"))}
query_id = {path: i for i, path in enumerate(lines("queries.txt"))}
truth = collections.defaultdict(set)
for r in csv.DictReader(open(f"{root}/ground_truth.csv")):
    truth[query_id[r["query"]]].add(map_id[r["match"]])
queries = collections.defaultdict(list)
for seed in (1, 2, 3):
    for r in csv.DictReader(open(f"{out}/{stem}-{seed}.csv")):
        row = {k: float(v) for k, v in r.items()}
        queries[(seed, row["query"])].append(row)

def place(c, cands):
    return sum(o["inliers"] for o in cands if abs(o["id"] - c["id"]) <= WINDOW)

def first(key):
    return lambda cands: max(cands, key=lambda c: key(c, cands))

by_place = first(lambda c, cands: (place(c, cands), c["inliers"], -c["rank"]))

def centre(cands):
    # the checked candidate of the place's nearest its inlier-weighted centre
    top = by_place(cands)
    near = [o for o in cands if abs(o["id"] - top["id"]) <= WINDOW]
    weight = sum(o["inliers"] for o in near)
    if weight == 0:
        return top
    at = sum(o["inliers"] * o["id"] for o in near) / weight
    return min(near, key=lambda o: (abs(o["id"] - at), o["rank"]))

def nearest_scale(verified_only):
    # verify.order = "place-scale": the place's verified candidate whose
    # inliers show the scene at the scale nearest the query's (or, not kept,
    # any of its candidates with inliers)
    def answer(cands):
        top = by_place(cands)
        near = [o for o in cands if abs(o["id"] - top["id"]) <= WINDOW
                and (o["verified"] if verified_only else o["inliers"] > 0)]
        return min(near, key=lambda o: (abs(math.log(o["scale"])), o["rank"])) if near else top
    return answer

answers = {
    "votes": first(lambda c, cands: (-c["rank"],)),
    "own inliers": first(lambda c, cands: (c["inliers"], -c["rank"])),
    "place, ties in vote order": first(lambda c, cands: (place(c, cands), -c["rank"])),
    "place, ties by own inliers": by_place,
    "place, answered by its inlier centre": centre,
    "place-scale": nearest_scale(True),
    "place-scale, any inliers": nearest_scale(False),
}
print(f"{label}: recall@1 (%), vocabulary seeds 1 / 2 / 3")
for name, answer in answers.items():
    right = collections.Counter()
    asked = collections.Counter()
    for (seed, _), cands in queries.items():
        asked[seed] += 1
        cands = [c for c in cands if c["rank"] >= 0]
        if cands:
            right[seed] += int(answer(cands)["correct"])
    print(f"  {name:36} " + " / ".join(f"{100 * right[s] / asked[s]:.1f}" for s in (1, 2, 3)))
for name in ("place, ties by own inliers", "place-scale"):
    off = collections.defaultdict(collections.Counter)
    for (seed, q), cands in queries.items():
        cands = [c for c in cands if c["rank"] >= 0]
        if cands and truth[int(q)]:
            top = answers[name](cands)
            if not top["correct"]:
                d = min(abs(int(top["id"]) - t) for t in truth[int(q)])
                off[seed][min(d, 4)] += 1
    print(f"  wrong answers ({name}), map images from the nearest right one, seeds 1 / 2 / 3:")
    for d in (1, 2, 3, 4):
        print(f"    {'4 or more' if d == 4 else d:9}  " + " / ".join(str(off[s][d]) for s in (1, 2, 3)))
# how the scale a verified candidate shows goes with where it was taken:
# map images from the middle of the query's right ones (all seeds)
scales = collections.defaultdict(list)
for (seed, q), cands in queries.items():
    right = sorted(truth[int(q)])
    if not right:
        continue
    middle = right[len(right) // 2]
    for c in cands:
        if c["rank"] >= 0 and c["verified"]:
            scales[max(-5, min(5, int(c["id"]) - middle))].append(math.log(c["scale"]))
print("  verified candidates, map images from the middle of the right ones: median relative scale")
print("    " + "  ".join(f"{d:+d}: {math.exp(statistics.median(v)):.2f}" for d, v in sorted(scales.items())))
PY
done
