#!/usr/bin/env bash
# Memory over many requests: drive a live `bowloc serve` on loopback with wrk
# in rounds and print the server's resident memory after each round, so a
# leak shows as a rising column. Rounds go on until REQUESTS requests have
# been answered (at most 100 rounds).
#
#   scripts/soak.sh [REQUESTS] [ROUND-SECONDS] [WORKERS] [CONNECTIONS]
#
# Defaults: 10 000 requests, rounds of 30 s, 2 workers, 4 connections. The map
# is rtabmap-loop (K = 1000); the image is one of its queries.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
requests=${1:-10000}
round_seconds=${2:-30}
workers=${3:-2}
connections=${4:-4}
load_prepare
tmp=$TMP
server_config "$workers" 32 >"$tmp/config.toml"
start_server "$tmp/config.toml" "$tmp/server.log"
echo "workers=$workers connections=$connections requests=$requests round_seconds=$round_seconds"
echo "round requests_total non_2xx_total requests_per_s server_rss_kib"
echo "0 0 0 - $(server_rss_kib)"
total=0
refused=0
round=0
while [ "$total" -lt "$requests" ] && [ "$round" -lt 100 ]; do
  round=$((round + 1))
  wrk -t 1 -c "$connections" -d "${round_seconds}s" -s "$tmp/post.lua" "http://$SERVER_ADDR/localize" >"$tmp/wrk.txt"
  total=$((total + $(awk '/requests in/ {print $1}' "$tmp/wrk.txt")))
  refused=$((refused + $(awk '/Non-2xx/ {n = $NF} END {print n + 0}' "$tmp/wrk.txt")))
  echo "$round $total $refused $(awk '/Requests\/sec/ {print $2}' "$tmp/wrk.txt") $(server_rss_kib)"
done
