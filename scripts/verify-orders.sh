#!/usr/bin/env bash
# What each order of the verified candidates gives, without a new search:
# runs examples/candidates.rs (every query's top 10 vote candidates of the
# full search, verified) for vocabulary seeds 1 to 3, then prints recall@1 per
# seed when the top candidate is taken
#   - by votes (no verification),
#   - by its own inliers (verify.order = "inliers"),
#   - by the inliers of its place, equal sums in vote order,
#   - by the inliers of its place, equal sums by its own inliers, then in
#     vote order (verify.order = "place").
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
queries = collections.defaultdict(list)
for seed in (1, 2, 3):
    for r in csv.DictReader(open(f"{out}/{stem}-{seed}.csv")):
        row = {k: float(v) for k, v in r.items()}
        queries[(seed, row["query"])].append(row)

def place(c, cands):
    return sum(o["inliers"] for o in cands if abs(o["id"] - c["id"]) <= WINDOW)

orders = {
    "votes": lambda c, cands: (-c["rank"],),
    "own inliers": lambda c, cands: (c["inliers"], -c["rank"]),
    "place, ties in vote order": lambda c, cands: (place(c, cands), -c["rank"]),
    "place, ties by own inliers": lambda c, cands: (place(c, cands), c["inliers"], -c["rank"]),
}
print(f"{label}: recall@1 (%), vocabulary seeds 1 / 2 / 3")
for name, key in orders.items():
    right = collections.Counter()
    asked = collections.Counter()
    for (seed, _), cands in queries.items():
        asked[seed] += 1
        cands = [c for c in cands if c["rank"] >= 0]
        if cands:
            right[seed] += int(max(cands, key=lambda c: key(c, cands))["correct"])
    print(f"  {name:28} " + " / ".join(f"{100 * right[s] / asked[s]:.1f}" for s in (1, 2, 3)))
PY
done
