#!/usr/bin/env bash
# Word pairs against descriptor matches for verification, without a new
# search: runs examples/candidates.rs with `descriptors` (every query's top 10
# vote candidates of the full search, verified from word pairs as the service
# does and also from nearest-neighbour descriptor matches passing Lowe's ratio
# test, the same homography fit) for vocabulary seeds 1 to 3. For each source
# of correspondences it prints, per seed:
#   - recall@1 with the candidates in verify.order = "place";
#   - recall top-1 @90 % precision with the answers cut by distinctness, by
#     the inliers of their place, and by the place's share of its own and the
#     best other place's inliers;
#   - the AUC with which each of these tells right answers from wrong ones;
#   - the median milliseconds per query to verify all candidates (one thread).
# A query without features counts as a miss.
#
#   scripts/verify-descriptors.sh [NAME:WORDS[:GRID] ...]
#     (default: gardens-point:5000:2x2+24 rtabmap-loop:1000:2x2+24)
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/candidates.sh
out=${OUT:-data/eval/verify-descriptors}
sets=("$@")
[ ${#sets[@]} -gt 0 ] || sets=(gardens-point:5000:2x2+24 rtabmap-loop:1000:2x2+24)
for set in "${sets[@]}"; do
  candidate_csvs "$out" "$set" descriptors
  python3 - "$out" "$STEM" "$set" <<'PY'
import collections, csv, sys

out, stem, label = sys.argv[1:]
WINDOW = 2  # search.place_window
SEEDS = (1, 2, 3)
queries = collections.defaultdict(list)
for seed in SEEDS:
    for r in csv.DictReader(open(f"{out}/{stem}-{seed}.csv")):
        queries[(seed, r["query"])].append({k: float(v) for k, v in r.items()})

def recall_at_90(pairs):
    """Best recall at precision >= 0.9 over cuts of (confidence, correct)."""
    pairs = sorted(pairs, key=lambda p: -p[0])
    best, i, right, answered = 0.0, 0, 0, 0
    while i < len(pairs):
        j = i
        while j < len(pairs) and pairs[j][0] == pairs[i][0]:
            right += pairs[j][1]
            answered += 1
            j += 1
        if right and right / answered >= 0.9 - 1e-12:
            best = max(best, right / len(pairs))
        i = j
    return best

def auc(pairs):
    pos = [v for v, c in pairs if c]
    neg = [v for v, c in pairs if not c]
    if not pos or not neg:
        return float("nan")
    return sum((a > b) + 0.5 * (a == b) for a in pos for b in neg) / len(pos) / len(neg)

CONFIDENCES = ("distinctness", "place inliers", "place share")
print(f"{label}: vocabulary seeds 1 / 2 / 3")
for source, key in (("word pairs", "inliers"), ("descriptor matches", "desc_inliers")):
    right = collections.defaultdict(int)
    conf = {c: collections.defaultdict(list) for c in CONFIDENCES}
    asked = collections.Counter()
    for (seed, _), cands in queries.items():
        asked[seed] += 1
        cands = [c for c in cands if c["rank"] >= 0]
        if not cands:
            for c in CONFIDENCES:
                conf[c][seed].append((-1.0, 0))
            continue
        for c in cands:
            c["place"] = sum(o[key] for o in cands if abs(o["id"] - c["id"]) <= WINDOW)
        top = max(cands, key=lambda c: (c["place"], c[key], -c["rank"]))
        other = max([c["place"] for c in cands if abs(c["id"] - top["id"]) > WINDOW] or [0])
        ok = int(top["correct"])
        right[seed] += ok
        conf["distinctness"][seed].append((top["distinct"], ok))
        conf["place inliers"][seed].append((top["place"], ok))
        share = top["place"] / (top["place"] + other) if top["place"] else 0.0
        conf["place share"][seed].append((share, ok))
    ms = sorted(cands[0][f"{'words' if key == 'inliers' else 'desc'}_ms"]
                for cands in queries.values() if cands[0]["rank"] >= 0)
    print(f"  {source}: recall@1 " + " / ".join(f"{100 * right[s] / asked[s]:.1f}" for s in SEEDS)
          + f"; verification {ms[len(ms) // 2]:.1f} ms per query, median of all seeds")
    for c in CONFIDENCES:
        print(f"    top-1 @90%P by {c:14} "
              + " / ".join(f"{100 * recall_at_90(conf[c][s]):.1f}" for s in SEEDS)
              + "   AUC " + " / ".join(f"{auc(conf[c][s]):.3f}" for s in SEEDS))
PY
done
