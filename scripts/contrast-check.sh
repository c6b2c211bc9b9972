#!/usr/bin/env bash
# SIFT's contrast threshold against recall and the verified stop, on both
# shared maps. For each threshold, `bowloc eval` (3 vocabulary seeds × 3
# feature orders, verification on) of the full search, the `verified` rule
# and the rule place-z 2 or verified 12, warm-up 20 (the default when the
# script was written; docs/results.md, "Denser keypoints", has a run of the
# current default too), then:
# the features per query; the full search's recall@1 per vocabulary seed
# without and with verification, and its recall top-1 @90 % precision (by
# distinctness, verified); the verified stop's share of the features and its
# recall@1; the default rule's share of the features, recall@1 and recall
# top-1 @90 % precision. Time is not compared here: each threshold is a
# separate run; `cargo bench --bench extract` prices the thresholds in one
# run.
#
#   scripts/contrast-check.sh                 # 0.04 (the default) 0.03 0.02 0.01
#   CONTRAST="0.04 0.03" scripts/contrast-check.sh
#
# Caches: data/eval-cache/contrast/DATASET-T; results: data/eval/contrast/DATASET-T.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=./target/release/bowloc
[ -x "$bin" ] || cargo build --release --quiet
thresholds=${CONTRAST:-0.04 0.03 0.02 0.01}
for spec in gardens-point:5000 rtabmap-loop:1000; do
  dataset=${spec%%:*} words=${spec##*:}
  for t in $thresholds; do
    out=data/eval/contrast/$dataset-$t
    "$bin" --log warn eval --dataset "../shared/datasets/$dataset" --words "$words" \
      --runs 3 --vocab-seeds 3 --verify --rules none --set verified=8 --set place-z=2+verified=12@20 \
      --tile-order random --contrast-threshold "$t" --no-plots \
      --cache "data/eval-cache/contrast/$dataset-$t" --out "$out" > /dev/null
    python3 - "$out/results.json" "$t" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
rows = {s["label"]: s for s in d["settings"]}
default = "place-z 2 or verified 12 w=20 +verify"
def seeds(label, key):
    return " / ".join(f"{v * 100:.1f}" for v in rows[label][key]["per_seed"])
print(
    f"{d['dataset']['name']} K={d['vocabularies'][0]['words']} contrast {sys.argv[2]}: "
    f"{d['dataset']['mean_features']:.0f} features per query (median {d['dataset']['median_features']})\n"
    f"  full search recall@1 {seeds('none', 'recall_at_1')}, "
    f"verified {seeds('none +verify', 'recall_at_1')}; "
    f"verified recall top-1 @90%P {seeds('none +verify', 'recall90_top1_distinct')}\n"
    f"  verified 8 stop: {rows['verified 8 +verify']['fraction']['mean'] * 100:.1f} % of the features, "
    f"recall@1 {seeds('verified 8 +verify', 'recall_at_1')}\n"
    f"  default rule: {rows[default]['fraction']['mean'] * 100:.1f} % of the features, "
    f"recall@1 {seeds(default, 'recall_at_1')}, "
    f"recall top-1 @90%P {seeds(default, 'recall90_top1_distinct')}"
)
PY
  done
done
