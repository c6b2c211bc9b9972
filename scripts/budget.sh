#!/usr/bin/env bash
# What a time budget (`budget_ms`) costs in recall and gives in time,
# through a live `bowloc serve` on loopback (default configuration, one
# request at a time). For each vocabulary seed's map, every query is sent in
# turn as the whole-image full search (rule=none&tiles=1x1), with the
# default configuration, and with the default configuration under each
# budget; the same seed for all, so only the budget differs. Prints, per
# setting: recall@1 and recall@5 per vocabulary seed (from the dataset's
# ground truth), the median and 95th percentile of the server's own request
# time (`timings_ms.total`, decoding to verification, what the budget
# counts), the share of answers the budget cut short and the share that
# ended past their budget.
#
#   [BUDGET_DATASET=rtabmap-loop] [BUDGET_SEEDS="1 2 3"] [BUDGET_BASELINE=BIN] scripts/budget.sh [BUDGETS…]
#
# BUDGET_BASELINE: another `bowloc` binary (an earlier build) serving the same
# map beside this one; every budget request is also sent to it, right after
# (or, every other query, right before) the same request to this build, and
# its answers are printed as rows "… baseline", so a change to how budgets
# are kept is compared in one run, on the machine at the same speed.
# BUDGET_DATASET: gardens-point (default; K = 5000 maps) or rtabmap-loop
# (K = 1000). BUDGETS: milliseconds (default: 20 30 40 for gardens-point,
# 8 12 16 for rtabmap-loop).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
name=${BUDGET_DATASET:-gardens-point}
seeds=${BUDGET_SEEDS:-1 2 3}
case $name in
  gardens-point) default_budgets="20 30 40" ;;
  rtabmap-loop) default_budgets="8 12 16" ;;
  *) echo "BUDGET_DATASET: gardens-point or rtabmap-loop, not $name" >&2; exit 2 ;;
esac
budgets=${*:-$default_budgets}
src=../shared/datasets/$name
tmp=$(mktemp -d)
base_pid=""
trap 'stop_server; [ -z "$base_pid" ] || kill "$base_pid" 2>/dev/null; rm -rf "$tmp"' EXIT
cargo build --release --quiet
map_for() {
  case $name in
    gardens-point) gardens_map 5000 "$1" >&2; map_dir data/gardens-5000 "$1" ;;
    rtabmap-loop) load_map "$1" >&2; map_dir data/load "$1" ;;
  esac
}
: >"$tmp/rows"
baseline=${BUDGET_BASELINE:-}
[ -z "$baseline" ] || [ -x "$baseline" ] || { echo "BUDGET_BASELINE: $baseline is not an executable" >&2; exit 2; }
# ask ADDR LABEL ASKED: the query $q (seed $n) with the parameters ASKED,
# its answer one row labelled LABEL
ask() {
  local addr=$1 label=$2 asked=$3
  curl -sf -o "$tmp/answer.json" -H 'Content-Type: image/jpeg' --data-binary @"$src/$q" \
    "http://$addr/localize?top_n=5&seed=$n${asked:+&$asked}"
  jq -r --arg s "$label" --arg seed "$seed" --arg q "$q" \
    '[$s, $seed, $q, .timings_ms.total, .stop.kind, ([.candidates[].name] | join(" "))] | @tsv' \
    "$tmp/answer.json" >>"$tmp/rows"
}
labels="full default"
for b in $budgets; do labels="$labels $b${baseline:+ $b-baseline}"; done
for seed in $seeds; do
  server_config 1 4 "$(map_for "$seed")" "" "" >"$tmp/server.toml"
  base_addr=""
  if [ -n "$baseline" ]; then
    ours=$BOWLOC_BIN
    BOWLOC_BIN=$baseline
    start_server "$tmp/server.toml" "$tmp/baseline.log"
    BOWLOC_BIN=$ours
    base_pid=$SERVER_PID
    base_addr=$SERVER_ADDR
  fi
  start_server "$tmp/server.toml" "$tmp/server.log"
  n=0
  while read -r q; do
    n=$((n + 1))
    ask "$SERVER_ADDR" full "rule=none&tiles=1x1"
    ask "$SERVER_ADDR" default ""
    for b in $budgets; do
      if [ -z "$base_addr" ]; then
        ask "$SERVER_ADDR" "$b" "budget_ms=$b"
      elif [ $((n % 2)) = 0 ]; then
        ask "$SERVER_ADDR" "$b" "budget_ms=$b"
        ask "$base_addr" "$b-baseline" "budget_ms=$b"
      else
        ask "$base_addr" "$b-baseline" "budget_ms=$b"
        ask "$SERVER_ADDR" "$b" "budget_ms=$b"
      fi
    done
  done <"$src/queries.txt"
  stop_server
  [ -z "$base_pid" ] || { kill -TERM "$base_pid"; wait "$base_pid" 2>/dev/null || true; base_pid=""; }
done
echo "$name: $(wc -l <"$src/queries.txt") queries × vocabulary seeds $seeds, one request at a time; $(lscpu | sed -n 's/^Model name: *//p')"
python3 - "$src/ground_truth.csv" "$tmp/rows" "$seeds" $labels <<'PY'
import csv, statistics, sys
truth, rows, seeds, settings = sys.argv[1], sys.argv[2], sys.argv[3].split(), sys.argv[4:]
right = {(r["query"], r["match"]) for r in csv.DictReader(open(truth))}
answers = [line.rstrip("\n").split("\t") for line in open(rows)]
print(f"{'setting':<16} {'recall@1 per seed':<22} {'recall@5 per seed':<22} {'ms median / p95':<16} {'cut short':<10} past budget")
for s in settings:
    mine = [a for a in answers if a[0] == s]
    def recall(k):
        per = []
        for seed in seeds:
            got = [a for a in mine if a[1] == seed]
            hit = sum(any((a[2], c) in right for c in a[5].split()[:k]) for a in got)
            per.append(f"{100 * hit / len(got):.1f}")
        return " / ".join(per)
    times = sorted(float(a[3]) for a in mine)
    p95 = times[min(len(times) - 1, round(0.95 * len(times)) - 1)]
    budget = float(s.removesuffix("-baseline")) if s[0].isdigit() else None
    cut = 100 * sum(a[4] == "budget" for a in mine) / len(mine)
    past = f"{100 * sum(float(a[3]) > budget for a in mine) / len(mine):.1f} %" if budget else "-"
    label = (f"budget {budget:g} ms" + (", baseline" if s.endswith("-baseline") else "")) if budget else s
    print(f"{label:<16} {recall(1):<22} {recall(5):<22} {f'{statistics.median(times):.1f} / {p95:.1f}':<16} {f'{cut:.1f} %':<10} {past}")
PY
