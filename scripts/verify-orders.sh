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
#     candidate of that place nearest its inlier-weighted centre (not kept);
# then, for verify.order = "place", how far its wrong answers are from the
# nearest right map image (in map images, along the map's order).
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
import collections, csv, sys

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

def centre(top, cands):
    # the checked candidate of top's place nearest its inlier-weighted centre
    near = [o for o in cands if abs(o["id"] - top["id"]) <= WINDOW]
    weight = sum(o["inliers"] for o in near)
    if weight == 0:
        return top
    at = sum(o["inliers"] * o["id"] for o in near) / weight
    return min(near, key=lambda o: (abs(o["id"] - at), o["rank"]))

orders = {
    "votes": lambda c, cands: (-c["rank"],),
    "own inliers": lambda c, cands: (c["inliers"], -c["rank"]),
    "place, ties in vote order": lambda c, cands: (place(c, cands), -c["rank"]),
    "place, ties by own inliers": lambda c, cands: (place(c, cands), c["inliers"], -c["rank"]),
}
print(f"{label}: recall@1 (%), vocabulary seeds 1 / 2 / 3")
place_key = orders["place, ties by own inliers"]
answers = dict(orders)
answers["place, answered by its inlier centre"] = None
for name, key in answers.items():
    right = collections.Counter()
    asked = collections.Counter()
    for (seed, _), cands in queries.items():
        asked[seed] += 1
        cands = [c for c in cands if c["rank"] >= 0]
        if cands:
            top = max(cands, key=lambda c: (key or place_key)(c, cands))
            right[seed] += int((top if key else centre(top, cands))["correct"])
    print(f"  {name:36} " + " / ".join(f"{100 * right[s] / asked[s]:.1f}" for s in (1, 2, 3)))
off = collections.defaultdict(collections.Counter)
for (seed, q), cands in queries.items():
    cands = [c for c in cands if c["rank"] >= 0]
    if cands and truth[int(q)]:
        top = max(cands, key=lambda c: place_key(c, cands))
        if not top["correct"]:
            d = min(abs(int(top["id"]) - t) for t in truth[int(q)])
            off[seed][min(d, 4)] += 1
print("  wrong answers (place order), map images from the nearest right one, seeds 1 / 2 / 3:")
for d in (1, 2, 3, 4):
    print(f"    {'4 or more' if d == 4 else d:9}  " + " / ".join(str(off[s][d]) for s in (1, 2, 3)))
PY
done
