#!/usr/bin/env bash
# Whether a time budget's tile prices come back after they were learnt on a
# slower machine. A live `bowloc serve` (gardens-point, K = 5000, vocabulary
# seed 1, default configuration) first answers RELEARN_SLOW requests (8)
# without a budget while two busy loops share its two cores, so the tiles it
# learns from cost more than they will; then the loops stop and it answers
# REQUESTS requests with budget_ms=BUDGET, the queries in turn, one at a
# time. Prints, per block of 32 of those requests, how many started with the
# coarse pass and their median request time (`timings_ms.total`), and the
# first three tiles' learnt time (`bowloc_tile_first_tiles_seconds`) after
# the slow requests and at the end.
#
#   [RELEARN_BASELINE=BIN] scripts/budget-relearn.sh [BUDGET] [REQUESTS]
#
# BUDGET: milliseconds (default 90); REQUESTS: default 256.
# RELEARN_PLAN: the extraction plan (search.tiles), e.g. "2x2+24" for the
# tiles alone; default: the configuration's.
# RELEARN_BASELINE: another `bowloc` binary (an earlier build), run the same
# way right after this one, its rows labelled "baseline".
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
budget=${1:-90}
requests=${2:-256}
slow=${RELEARN_SLOW:-8}
src=../shared/datasets/gardens-point
tmp=$(mktemp -d)
hogs=""
trap 'stop_server; [ -z "$hogs" ] || kill $hogs 2>/dev/null; rm -rf "$tmp"' EXIT
cargo build --release --quiet
baseline=${RELEARN_BASELINE:-}
[ -z "$baseline" ] || [ -x "$baseline" ] || { echo "RELEARN_BASELINE: $baseline is not an executable" >&2; exit 2; }
gardens_map 5000 1 >&2
plan=${RELEARN_PLAN:+[search]
tiles = \"$RELEARN_PLAN\"}
server_config 1 4 "$(map_dir data/gardens-5000 1)" "$plan" "" >"$tmp/server.toml"
mapfile -t queries <"$src/queries.txt"
first_tiles_ms() {
  curl -sf "http://$SERVER_ADDR/metrics" |
    awk '/^bowloc_tile_first_tiles_seconds / {printf "%.1f", $2 * 1000}'
}
# run LABEL BIN: the slow requests, then the budgeted ones, summed up
run() {
  local label=$1 ours=$BOWLOC_BIN
  BOWLOC_BIN=$2
  start_server "$tmp/server.toml" "$tmp/server.log"
  BOWLOC_BIN=$ours
  for _ in 1 2; do (while :; do :; done) & hogs="$hogs $!"; done
  for ((i = 0; i < slow; i++)); do
    curl -sf -o /dev/null -H 'Content-Type: image/jpeg' --data-binary @"$src/${queries[i]}" \
      "http://$SERVER_ADDR/localize?seed=$i"
  done
  kill $hogs
  wait $hogs 2>/dev/null || true
  hogs=""
  local learnt
  learnt=$(first_tiles_ms)
  : >"$tmp/rows"
  for ((i = 0; i < requests; i++)); do
    q=${queries[$((i % ${#queries[@]}))]}
    curl -sf -H 'Content-Type: image/jpeg' --data-binary @"$src/$q" \
      "http://$SERVER_ADDR/localize?seed=$i&budget_ms=$budget" |
      jq -r '[(.tiles.grid | test(",coarse") | tostring), .timings_ms.total] | @tsv' >>"$tmp/rows"
  done
  echo "$label: first three tiles learnt at $learnt ms after the slow requests, $(first_tiles_ms) ms at the end"
  python3 - "$tmp/rows" <<'PY'
import statistics, sys
rows = [line.split("\t") for line in open(sys.argv[1])]
for start in range(0, len(rows), 32):
    block = rows[start:start + 32]
    coarse = sum(r[0] == "true" for r in block)
    ms = statistics.median(float(r[1]) for r in block)
    print(f"  requests {start + 1:>3}-{start + len(block):<3}  coarse pass first {coarse:>2} of {len(block)}  median {ms:.1f} ms")
PY
  stop_server
}
echo "gardens-point, plan ${RELEARN_PLAN:-of the configuration}, budget $budget ms, $slow requests with two busy loops first; $(lscpu | sed -n 's/^Model name: *//p')"
run "this build" "$BOWLOC_BIN"
[ -z "$baseline" ] || run baseline "$baseline"
