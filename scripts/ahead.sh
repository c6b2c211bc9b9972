#!/usr/bin/env bash
# What extracting tiles ahead on a spare core (`server.tiles_ahead`) does to
# latency and throughput, from one request at a time to a saturated server:
# a real `bowloc serve` on loopback (the default configuration, gardens-point
# K = 5000 map of vocabulary seed 1, built on first use) takes gardens-point
# queries (every 10th, in turn) from wrk with each number of connections
# (AHEAD_DATASET=rtabmap-loop: its K = 1000 map and every one of its queries),
# once with tiles ahead off and once on, taking turns for ROUNDS rounds so a
# slow spell of the machine falls on both alike. Prints, per connection
# count and setting, the medians over rounds of requests per second and of
# wrk's latency percentiles (50, 90 and 99 %), and the ratios on/off.
#
#   [AHEAD_DATASET=rtabmap-loop] scripts/ahead.sh [CONNECTIONS,...] [SECONDS] [ROUNDS]
#
# Defaults: 1,2,4 connections; 10 s; 3 rounds. Run it on a quiet machine.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
command -v wrk >/dev/null || { echo "wrk missing: apt-get install wrk" >&2; exit 1; }
IFS=, read -ra connection_counts <<<"${1:-1,2,4}"
seconds=${2:-10}
rounds=${3:-3}
dataset=${AHEAD_DATASET:-gardens-point}
case $dataset in
  gardens-point) gardens_map 5000 1; map=data/gardens-5000; every=10 ;;
  rtabmap-loop) load_map 1; map=data/load; every=1 ;;
  *) echo "AHEAD_DATASET: gardens-point or rtabmap-loop, not $dataset" >&2; exit 2 ;;
esac
tmp=$(mktemp -d)
trap 'stop_server; rm -rf "$tmp"' EXIT
src=../shared/datasets/$dataset
{
  echo 'local paths = {'
  awk -v every="$every" 'NR % every == 1 % every' "$src/queries.txt" |
    while read -r q; do echo "  \"$src/$q\","; done
  echo '}'
  cat <<'LUA'
local bodies = {}
for _, p in ipairs(paths) do
  local f = assert(io.open(p, "rb"))
  bodies[#bodies + 1] = f:read("*all")
  f:close()
end
local i = 0
wrk.method = "POST"
wrk.headers["Content-Type"] = "image/jpeg"
request = function()
  i = i % #bodies + 1
  return wrk.format(nil, nil, nil, bodies[i])
end
LUA
} >"$tmp/post.lua"
server_config 0 32 "$map" "" "" >"$tmp/config.toml"
# ms from wrk's "50%   12.34ms" lines (us and s converted)
to_ms() { awk '{v = $2; u = v; sub(/[0-9.]+/, "", u); sub(/[a-z]+$/, "", v);
  if (u == "us") v /= 1000; else if (u == "s") v *= 1000; printf "%.2f\n", v}'; }
# tiles the server has extracted ahead and used so far
tiles_ahead() {
  curl -s "http://$SERVER_ADDR/metrics" |
    awk '/^bowloc_localize_tiles_ahead_total\{used="true"\}/ {n = $2} END {print n + 0}'
}
for round in $(seq "$rounds"); do
  for c in "${connection_counts[@]}"; do
    for ahead in false true; do
      BOWLOC_SERVER__TILES_AHEAD=$ahead start_server "$tmp/config.toml" "$tmp/server.log"
      # one pass over the queries first: the learned plan's trials
      wrk -t 1 -c 1 -d 3s -s "$tmp/post.lua" "http://$SERVER_ADDR/localize" >/dev/null
      before=$(tiles_ahead)
      wrk -t 1 -c "$c" -d "${seconds}s" --latency -s "$tmp/post.lua" \
        "http://$SERVER_ADDR/localize" >"$tmp/wrk.txt"
      ahead_used=$(($(tiles_ahead) - before))
      stop_server
      rps=$(awk '/Requests\/sec/ {print $2}' "$tmp/wrk.txt")
      p50=$(grep -E '^ +50%' "$tmp/wrk.txt" | to_ms)
      p90=$(grep -E '^ +90%' "$tmp/wrk.txt" | to_ms)
      p99=$(grep -E '^ +99%' "$tmp/wrk.txt" | to_ms)
      non2xx=$(awk '/Non-2xx/ {n = $NF} END {print n + 0}' "$tmp/wrk.txt")
      echo "round $round: connections=$c tiles_ahead=$ahead requests_per_s=$rps" \
        "latency_p50=${p50}ms latency_p90=${p90}ms latency_p99=${p99}ms non_2xx=$non2xx" \
        "tiles_used_ahead=$ahead_used"
      echo "$c $ahead $rps $p50 $p90 $p99" >>"$tmp/rows"
    done
  done
done
echo "$dataset; $(lscpu | sed -n 's/^Model name: *//p'), $(nproc) CPUs; medians over $rounds rounds of ${seconds} s"
# per connection count, each column's median over rounds off and on, and on/off
for c in "${connection_counts[@]}"; do
  line="connections=$c:"
  sep=""
  for col in "3 requests/s " "4 p50 ms" "5 p90 ms" "6 p99 ms"; do
    read -r k name unit <<<"$col"
    off=$(awk -v c="$c" -v k="$k" '$1 == c && $2 == "false" {print $k}' "$tmp/rows" | median)
    on=$(awk -v c="$c" -v k="$k" '$1 == c && $2 == "true" {print $k}' "$tmp/rows" | median)
    line+=$(awk -v n="$name" -v u="${unit:+ $unit}" -v a="$off" -v b="$on" -v s="$sep" \
      'BEGIN {printf "%s %s %.1f off, %.1f on%s (%.3fx)", s, n, a, b, u, b / a}')
    sep=";"
  done
  echo "$line"
done
