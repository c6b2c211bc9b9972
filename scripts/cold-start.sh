#!/usr/bin/env bash
# What a server's first requests cost, with its workers warmed up before it
# is ready (`server.warm_up = true`, the default) and without: the server is
# started RESTARTS times each way, alternately, on the gardens-point map
# (K = 5000, vocabulary seed 1), and answers the same QUERIES queries in
# turn (every 10th query of the dataset, the default configuration and
# rule), then the same queries again (by then its workers are warm either
# way). Prints, for each request position, the median over restarts of the
# client's time and of the SIFT extraction the answer reports, both ways,
# their ratio, and how long the warm-up held readiness back.
#
#   [RESTARTS=5] [QUERIES=4] scripts/cold-start.sh
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
restarts=${RESTARTS:-5}
count=${QUERIES:-4}
src=../shared/datasets/gardens-point
tmp=$(mktemp -d)
trap 'stop_server; rm -rf "$tmp"' EXIT
gardens_map 5000 1
server_config 0 8 data/gardens-5000 >"$tmp/config.toml"
mapfile -t queries < <(awk 'NR % 10 == 1' "$src/queries.txt" | head -n "$count")
: >"$tmp/rows"
for restart in $(seq "$restarts"); do
  for warm in true false; do
    BOWLOC_SERVER__WARM_UP=$warm start_server "$tmp/config.toml" "$tmp/server.log"
    if [ "$warm" = true ]; then
      grep -o 'workers warmed up.*' "$tmp/server.log" | grep -o 'ms=[0-9.]*' | cut -d= -f2 >>"$tmp/warm_ms"
    fi
    position=0
    for round in first again; do
      for q in "${queries[@]}"; do
        position=$((position + 1))
        client=$(curl -s -o "$tmp/answer.json" -w '%{time_total}' -H 'Content-Type: image/jpeg' \
          --data-binary @"$src/$q" "http://$SERVER_ADDR/localize?seed=$restart")
        jq -r --arg c "$client" --arg w "$warm" --arg p "$position" --arg r "$round" \
          '[$w, $r, $p, ($c | tonumber) * 1000, .timings_ms.extract] | @tsv' \
          "$tmp/answer.json" >>"$tmp/rows"
      done
    done
    stop_server
  done
done
# median of column $4 of the rows matching warm $1, position $2, column $3
cell() { awk -F'\t' -v w="$1" -v p="$2" -v c="$3" '$1 == w && $3 == p {print $c}' "$tmp/rows" | median; }
echo "gardens-point, $restarts restarts each way; medians over restarts (ms): client time, extraction"
printf '%-8s %-6s %-23s %-23s %s\n' request round "warm: client, extract" "cold: client, extract" "ratio of client times"
for position in $(seq $((2 * count))); do
  round=$([ "$position" -le "$count" ] && echo first || echo again)
  wc=$(cell true "$position" 4) we=$(cell true "$position" 5)
  cc=$(cell false "$position" 4) ce=$(cell false "$position" 5)
  printf '%-8s %-6s %10.1f %12.1f %10.1f %12.1f %8.3f\n' "$position" "$round" \
    "$wc" "$we" "$cc" "$ce" "$(awk -v a="$wc" -v b="$cc" 'BEGIN {print a / b}')"
done
printf 'warm-up before ready: median %.1f ms\n' "$(median <"$tmp/warm_ms")"
