#!/usr/bin/env bash
# How wide a place should be for distinctness: the full search on both
# shared datasets (3 vocabulary seeds × 3 feature orders) with each place
# window, and the recall of the top candidate at 90 % precision when the
# answers are cut by distinctness (mean ± std over seeds, worst seed; %).
#
#   scripts/place-window-check.sh [OUT]     (default OUT: data/eval/place-window)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-data/eval/place-window}
[ -x target/release/bowloc ] || cargo build --release
for dataset in gardens-point:5000 rtabmap-loop:1000; do
  name=${dataset%%:*}
  words=${dataset##*:}
  for window in ${WINDOWS:-1 2 3 5}; do
    dir="$out/$name-w$window"
    ./target/release/bowloc --log warn eval --dataset "../shared/datasets/$name" --words "$words" \
      --runs 3 --vocab-seeds 3 --rules none --place-window "$window" --no-plots --out "$dir" >/dev/null
    python3 - "$dir/results.csv" "$name" "$window" <<'PY'
import csv, sys
r = next(csv.DictReader(open(sys.argv[1])))
pct = lambda k: 100 * float(r[k])
print(f"{sys.argv[2]:14} place window {sys.argv[3]}: recall top-1 @90%P by distinctness "
      f"{pct('recall90_top1_distinct_mean'):.1f} ± {pct('recall90_top1_distinct_seed_std'):.1f} "
      f"(worst seed {pct('recall90_top1_distinct_worst'):.1f})")
PY
  done
done
