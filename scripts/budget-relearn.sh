#!/usr/bin/env bash
# A server whose every request has a time budget: what it learns, and
# whether tile prices learnt on a slower machine come back. A live
# `bowloc serve` (gardens-point with K = 5000, or rtabmap-loop with K = 1000;
# vocabulary seed RELEARN_SEED, default 1; default configuration) first answers RELEARN_SLOW requests (8) without a budget
# while two busy loops share its two cores, so the tiles it learns from cost
# more than they will; then the loops stop and it answers REQUESTS requests
# with budget_ms=BUDGET, the queries in turn, one at a time. Prints, per
# block of 32 of those requests, how many started with the coarse pass and
# their median request time (`timings_ms.total`); over all of them, the
# same with the 95th percentile and recall@1 (from the ground truth); and the
# first three tiles' learnt time (`bowloc_tile_first_tiles_seconds`) after
# the slow requests and at the end.
#
#   [RELEARN_DATASET=rtabmap-loop] [RELEARN_SEED=2] [RELEARN_BASELINE=BIN] [RELEARN_PLAN=GRID] scripts/budget-relearn.sh [BUDGET] [REQUESTS]
#
# BUDGET: milliseconds (default 90); REQUESTS: default 256.
# RELEARN_PLAN: the extraction plan (search.tiles), e.g. "2x2+24" for the
# tiles alone; default: the configuration's.
# RELEARN_BASELINE: another `bowloc` binary (an earlier build) serving beside
# this one; each request goes to both, one right after the other (in turns
# which first), so the two are compared in one run on the machine at the
# same speed. Its rows are labelled "baseline".
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
budget=${1:-90}
requests=${2:-256}
slow=${RELEARN_SLOW:-8}
name=${RELEARN_DATASET:-gardens-point}
seed=${RELEARN_SEED:-1}
src=../shared/datasets/$name
tmp=$(mktemp -d)
hogs=""
pids=""
trap '[ -z "$hogs" ] || kill $hogs 2>/dev/null; [ -z "$pids" ] || kill $pids 2>/dev/null; rm -rf "$tmp"' EXIT
cargo build --release --quiet
baseline=${RELEARN_BASELINE:-}
[ -z "$baseline" ] || [ -x "$baseline" ] || { echo "RELEARN_BASELINE: $baseline is not an executable" >&2; exit 2; }
case $name in
  gardens-point) gardens_map 5000 "$seed" >&2; dir=$(map_dir data/gardens-5000 "$seed") ;;
  rtabmap-loop) load_map "$seed" >&2; dir=$(map_dir data/load "$seed") ;;
  *) echo "RELEARN_DATASET: gardens-point or rtabmap-loop, not $name" >&2; exit 2 ;;
esac
plan=${RELEARN_PLAN:+[search]
tiles = \"$RELEARN_PLAN\"}
server_config 1 4 "$dir" "$plan" "" >"$tmp/server.toml"
mapfile -t queries <"$src/queries.txt"
# the servers: label, binary
labels=("this build") bins=("$BOWLOC_BIN") addrs=()
[ -z "$baseline" ] || { labels+=(baseline); bins+=("$baseline"); }
ours=$BOWLOC_BIN
for k in "${!bins[@]}"; do
  BOWLOC_BIN=${bins[k]}
  start_server "$tmp/server.toml" "$tmp/server-$k.log"
  addrs+=("$SERVER_ADDR")
  pids="$pids $SERVER_PID"
  SERVER_PID=""
done
BOWLOC_BIN=$ours
first_tiles_ms() {
  curl -sf "http://$1/metrics" | awk '/^bowloc_tile_first_tiles_seconds / {printf "%.1f", $2 * 1000}'
}
for _ in 1 2; do (while :; do :; done) & hogs="$hogs $!"; done
for ((i = 0; i < slow; i++)); do
  for addr in "${addrs[@]}"; do
    curl -sf -o /dev/null -H 'Content-Type: image/jpeg' --data-binary @"$src/${queries[i]}" \
      "http://$addr/localize?seed=$i"
  done
done
kill $hogs
wait $hogs 2>/dev/null || true
hogs=""
learnt=()
for addr in "${addrs[@]}"; do learnt+=("$(first_tiles_ms "$addr")"); done
: >"$tmp/rows"
for ((i = 0; i < requests; i++)); do
  q=${queries[$((i % ${#queries[@]}))]}
  order=("${!addrs[@]}")
  [ $((i % 2)) = 0 ] || order=($(printf '%s\n' "${order[@]}" | tac))
  for k in "${order[@]}"; do
    curl -sf -H 'Content-Type: image/jpeg' --data-binary @"$src/$q" \
      "http://${addrs[k]}/localize?seed=$i&budget_ms=$budget" |
      jq -r --arg k "$k" --argjson i "$i" --arg q "$q" \
        '[$k, $i, $q, (.tiles.grid | test(",coarse") | tostring), .timings_ms.total, (.candidates[0].name // "")] | @tsv' \
        >>"$tmp/rows"
  done
done
echo "$name (vocabulary seed $seed), plan ${RELEARN_PLAN:-of the configuration}, budget $budget ms, $slow requests with two busy loops first; $(lscpu | sed -n 's/^Model name: *//p')"
for k in "${!addrs[@]}"; do
  echo "${labels[k]}: first three tiles learnt at ${learnt[k]} ms after the slow requests, $(first_tiles_ms "${addrs[k]}") ms at the end"
  python3 - "$tmp/rows" "$k" "$src/ground_truth.csv" <<'PY'
import csv, statistics, sys
right = {(r["query"], r["match"]) for r in csv.DictReader(open(sys.argv[3]))}
rows = [line.rstrip("\n").split("\t") for line in open(sys.argv[1])]
rows = [r for r in rows if r[0] == sys.argv[2]]
for start in range(0, len(rows), 32):
    block = rows[start:start + 32]
    coarse = sum(r[3] == "true" for r in block)
    ms = statistics.median(float(r[4]) for r in block)
    print(f"  requests {start + 1:>3}-{start + len(block):<3}  coarse pass first {coarse:>2} of {len(block)}  median {ms:.1f} ms")
times = sorted(float(r[4]) for r in rows)
p95 = times[min(len(times) - 1, round(0.95 * len(times)) - 1)]
coarse = sum(r[3] == "true" for r in rows)
recall = 100 * sum((r[2], r[5]) in right for r in rows) / len(rows)
print(f"  all {len(rows)}: coarse pass first {coarse}, median {statistics.median(times):.1f} ms, p95 {p95:.1f} ms, recall@1 {recall:.1f}")
PY
done
