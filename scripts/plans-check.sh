#!/usr/bin/env bash
# The two streaming-extraction plans the service chooses between
# (search.tiles = "2x2+24,auto"): plain tiles and the coarse pass first, on
# both shared datasets, for the full search, the default rule and the
# verified stop. Prints one line per dataset, plan and setting: recall@1
# (mean and worst vocabulary seed), recall@5, recall top-1 @90%P by
# distinctness, the share of features used, and the request time against
# the whole-image full search (mean and median over seeds × queries × runs).
#
#   scripts/plans-check.sh [OUT]      (default OUT: data/eval/plans)
#
# The environment changes what is compared: SETTINGS (RULE=VALUE@WARMUP
# settings besides the full search; default "peak-mean=1.6@20 verified=8"),
# VERIFY (yes or no; default yes), PLANS (default "2x2+24 2x2+24,coarse";
# "2x2+24,auto" replays the service's learned choice between them),
# ORDERS (tile orders, default "richest"; "richest random" compares them)
# and DATASETS (NAME:WORDS, default "rtabmap-loop:1000 gardens-point:5000").
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-data/eval/plans}
settings=()
for s in ${SETTINGS:-peak-mean=1.6@20 verified=8}; do settings+=(--set "$s"); done
verify=()
[ "${VERIFY:-yes}" = yes ] && verify=(--verify)
[ -x target/release/bowloc ] || cargo build --release
for dataset in ${DATASETS:-rtabmap-loop:1000 gardens-point:5000}; do
  name=${dataset%%:*}
  words=${dataset##*:}
  for plan in ${PLANS:-2x2+24 2x2+24,coarse}; do
  for order in ${ORDERS:-richest}; do
    dir="$out/$name-$plan-$order"
    ./target/release/bowloc --log warn eval --dataset "../shared/datasets/$name" --words "$words" \
      --runs 3 --vocab-seeds 3 --rules none --tiles "$plan" --tile-order "$order" "${verify[@]}" \
      "${settings[@]}" --no-plots --out "$dir" >/dev/null
    python3 - "$dir/results.csv" "$name" "$plan $order" <<'PY'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1])))
seen = set()
for r in rows:
    key = (r["rule"], r["parameter"], r["min_features"])
    if key in seen:
        continue
    seen.add(key)
    label = " ".join(x for x in (r["rule"], r["parameter"]) if x)
    if r["min_features"] != "0":
        label += f" w={r['min_features']}"
    pct = lambda k: 100 * float(r[k])
    print(f"{sys.argv[2]:14} {sys.argv[3]:23} {label:20} recall@1 {pct('recall1_mean'):.1f} "
          f"(worst {pct('recall1_worst'):.1f}), recall@5 {pct('recall5_mean'):.1f}, "
          f"top-1 @90%P by distinctness {pct('recall90_top1_distinct_mean'):.1f}, "
          f"features {pct('fraction_mean'):.1f} %, x whole-image full search "
          f"{float(r['time_share_whole_full_mean']):.3f} / {float(r['time_share_whole_full_median']):.3f}"
          + (f", started coarse {pct('coarse_first_mean'):.1f} %" if r.get('coarse_first_mean') and float(r['coarse_first_mean']) > 0 else ""))
PY
  done
  done
done
