#!/usr/bin/env bash
# Memory over many requests: drive a live `bowloc serve` on loopback with wrk
# in rounds of a fixed number of requests and print the server's resident
# memory after each round, so a leak shows as a rising column.
#
#   scripts/soak.sh [REQUESTS] [ROUNDS] [WORKERS] [CONNECTIONS]
#
# Defaults: 10 000 requests in 10 rounds, 2 workers, 4 connections. The map is
# rtabmap-loop (K = 1000); the image is one of its queries. Each round is
# bounded to 10 minutes.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
requests=${1:-10000}
rounds=${2:-10}
workers=${3:-2}
connections=${4:-4}
command -v wrk >/dev/null || { echo "wrk missing: apt-get install wrk" >&2; exit 1; }
load_map
tmp=$(mktemp -d)
server_config "$workers" 32 >"$tmp/config.toml"
start_server "$tmp/config.toml" "$tmp/server.log"
trap 'kill $SERVER_PID 2>/dev/null; wait $SERVER_PID 2>/dev/null; rm -rf "$tmp"' EXIT
threads=2
per_thread=$(( (requests / rounds + threads - 1) / threads ))
wrk_post_script "$tmp/post.lua" "$DATA/images/50.jpg" "$per_thread"
echo "workers=$workers connections=$connections requests=$requests rounds=$rounds"
echo "round requests_total non_2xx_total requests_per_s server_rss_kib"
echo "0 0 0 - $(rss_kib)"
total=0
refused=0
for round in $(seq "$rounds"); do
  wrk -t $threads -c "$connections" -d 600s -s "$tmp/post.lua" "http://$ADDR/localize" >"$tmp/wrk.txt"
  total=$((total + $(awk '/requests in/ {print $1}' "$tmp/wrk.txt")))
  refused=$((refused + $(awk '/Non-2xx/ {print $NF}' "$tmp/wrk.txt" | grep . || echo 0)))
  echo "$round $total $refused $(awk '/Requests\/sec/ {print $2}' "$tmp/wrk.txt") $(rss_kib)"
done
