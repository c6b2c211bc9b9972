#!/usr/bin/env bash
# An ORB pass before SIFT, measured: runs examples/orb_pass.rs on both
# shared datasets with the maps scripts/latency.sh uses (gardens-point
# K = 5000, rtabmap-loop K = 1000), vocabulary seeds 1 to 3 (each built on
# first use). For each it prints the full search's and the service's
# default's recall and median time, and for each setting of the pass the
# queries it answered, recall@1 and recall@5 against the full search and
# the median ratio of the request time to the full search's
# (docs/performance.md, "An ORB pass before SIFT").
#
# Then it chooses settings from the sweep on one set of queries and
# checks them on another (choose() below says how): chosen on
# gardens-point and checked on rtabmap-loop, the other way round, and
# chosen on the even queries of both datasets and checked on the odd ones;
# and it counts the settings within the bar on both datasets at once.
# With the reversed sets (below), it also chooses on both datasets at once
# and checks on both reversed sets.
#
#   scripts/orb-pass.sh [SEEDS]      (default "1 2 3")
#
# ORB_PASS_REVERSED=1 also runs both datasets with their map and queries
# swapped (scripts/reversed-datasets.sh; their maps built on first use)
# and checks every choice made on gardens-point on them too, as two more
# sets held out; they are never chosen on.
# ORB_PASS_GRID, ORB_PASS_TOP and ORB_PASS_KEYPOINTS pass to the example (its
# module comment).
# SWEEP_KEEP=FILE keeps the sweep's lines; SWEEP_FROM=FILE chooses from
# kept lines without measuring again; CHOOSE_LOSS lists the losses allowed
# where chosen (default "0.5 1", each in turn).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
seeds=${1:-1 2 3}
losses=${CHOOSE_LOSS:-0.5 1}
sweep=$(mktemp)
trap 'rm -f "$sweep"' EXIT
run() {
  local out
  out=$(./target/release/examples/orb_pass "$@")
  grep -v '^sweep' <<<"$out"
  grep '^sweep' <<<"$out" | grep -v '^sweep.dataset' >>"$sweep"
}
if [ -n "${SWEEP_FROM:-}" ]; then
  cp "$SWEEP_FROM" "$sweep"
else
  cargo build --release --example orb_pass >&2
  # the example on dataset folder $1 with its maps of $2 words in $3 (seed
  # 1) or $3-sSEED, named $4, for every seed
  run_set() {
    local seed dir
    for seed in $seeds; do
      dataset_map "$1" "$2" "$seed" "$3" "${4:-}" >&2
      dir=$(map_dir "$3" "$seed")
      run "$1" "$dir/vocab.bowvoc" "$dir/map.bowmap"
    done
  }
  run_set ../shared/datasets/gardens-point 5000 data/gardens-5000 gardens-point
  run_set "$DATASET" 1000 data/load
  if [ -n "${ORB_PASS_REVERSED:-}" ]; then
    scripts/reversed-datasets.sh >&2
    run_set data/datasets/gardens-point-reversed 5000 data/gardens-point-reversed-5000 gardens-point-reversed
    run_set data/datasets/rtabmap-loop-reversed 1000 data/rtabmap-loop-reversed-1000 rtabmap-loop-reversed
  fi
  if [ -n "${SWEEP_KEEP:-}" ]; then cp "$sweep" "$SWEEP_KEEP"; fi
fi
# columns: sweep dataset seed part pick floor window margin agree answered
# d1full d5full d1default d5default ratio; a set is dataset/part, part
# all, even (queries 0, 2, 4, …) or odd (1, 3, 5, …). The bar: median
# per-query ratio at most 0.6 on gardens-point, 0.5 on rtabmap-loop (and
# the same on each reversed).
#
# choose "SETS CHOSEN ON" "SETS CHECKED ON": of the settings that lose at
# most $loss points of recall@1 and of recall@5 against the default alone
# on every seed of every set chosen on, the ones within 0.01 of the lowest
# worst ratio-to-bar there; then how many hold on the sets checked on
# (every seed: recall within 1 point of the full search, or of the
# default alone, and the ratio within the bar), and the fastest there.
# what both awk programs below read a sweep line by: the setting's name
# and the dataset's bar
settings_awk='
  function setting() { return $5 " floor " $6 " window " $7 " margin " $8 ($9 == "true" ? " agree" : "") }
  function bar() { return ($2 ~ /^gardens-point/) ? 0.6 : 0.5 }'
choose() {
  local on=$1 other=$2
  echo "chosen on $on (at most $loss points of recall@1 and of recall@5 lost against the default alone on every seed; within 0.01 of the lowest worst ratio to the bar), checked on $other (held out):"
  local out
  out=$(awk -F'\t' -v on=" $on " -v other=" $other " -v loss="$loss" "$settings_awk"'
    function worse(a, k, v) { if (!(k in a) || v < a[k]) a[k] = v }
    function slower(a, k, v) { if (!(k in a) || v > a[k]) a[k] = v }
    { key = setting()
      set = " " $2 "/" $4 " "
      to_bar = $15 / bar()
      if (index(on, set)) {
        worse(low, key, $13); worse(low, key, $14); slower(slow, key, to_bar)
      } else if (index(other, set)) {
        worse(held, key, $11); worse(held, key, $12)
        worse(held_default, key, $13); worse(held_default, key, $14)
        slower(hslow, key, to_bar)
      } }
    END {
      best = ""
      for (k in low) if (low[k] >= -loss && (best == "" || slow[k] < slow[best])) best = k
      if (best == "") exit
      n = 0; met = 0; met_default = 0
      for (k in low) if (low[k] >= -loss && slow[k] <= slow[best] + 0.01) {
        n++
        if (held[k] >= -1 && hslow[k] <= 1) met++
        if (held_default[k] >= -1 && hslow[k] <= 1) met_default++
        printf "%.3f\t  %s: worst ratio to the bar %.3f where chosen; held out: worst change against the full search %+.1f, against the default %+.1f, worst ratio to the bar %.3f\n", hslow[k], k, slow[k], held[k], held_default[k], hslow[k]
      }
      printf "summary\t  %d settings chosen; held out, %d of them keep within 1 point of the full search and %d within 1 point of the default alone, within the bar, on every seed; the fastest there:\n", n, met, met_default
    }' "$sweep")
  grep '^summary' <<<"$out" | cut -f2- || echo "  no setting qualifies"
  { grep -v '^summary' <<<"$out" || true; } | sort -g | sed -n "1,${CHOOSE_SHOW:-6}p" | cut -f2-
}
reversed=$(awk -F'\t' '$2 ~ /-reversed$/ {print $2; exit}' "$sweep")
for loss in $losses; do
  choose "gardens-point/all" "rtabmap-loop/all"
  if [ -n "$reversed" ]; then
    choose "gardens-point/all" "gardens-point-reversed/all"
    choose "gardens-point/all" "rtabmap-loop-reversed/all"
  fi
  choose "rtabmap-loop/all" "gardens-point/all"
  choose "gardens-point/even rtabmap-loop/even" "gardens-point/odd rtabmap-loop/odd"
  if [ -n "$reversed" ]; then
    choose "gardens-point/all rtabmap-loop/all" "gardens-point-reversed/all rtabmap-loop-reversed/all"
  fi
done
# the bar on both datasets at once (all queries, every seed)
echo "settings within the bar on both datasets, every seed (all queries):"
awk -F'\t' "$settings_awk"'
  $4 == "all" && $2 !~ /-reversed$/ { key = setting()
    if ($11 < -1 || $12 < -1 || $15 > bar()) fail[key] = 1
    if ($13 < -1 || $14 < -1 || $15 > bar()) fail_default[key] = 1
    seen[key] = 1
    if (!(key in slow) || $15 / bar() > slow[key]) slow[key] = $15 / bar()
  }
  END { n = 0; m = 0; for (k in seen) { if (!(k in fail)) n++; if (!(k in fail_default)) m++ }
        printf "  %d of %d settings keep within 1 point of the full search, %d within 1 point of the default alone:\n", n, length(seen), m
        for (k in seen) if (!(k in fail_default)) printf "  %s (worst ratio to the bar %.3f)\n", k, slow[k] }' "$sweep"
