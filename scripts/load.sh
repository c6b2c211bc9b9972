#!/usr/bin/env bash
# Drive a real `bowloc serve` on loopback with wrk and report requests per
# second, latency percentiles, refused (non-2xx) requests and the server's
# memory before and after. Bounded in time; the server is stopped at the end.
#
#   scripts/load.sh [WORKERS] [CONNECTIONS] [SECONDS] [QUEUE]
#
# Defaults: 2 workers, 8 connections, 20 s, queue 32. The map is rtabmap-loop
# (K = 1000), built into data/load/ on first use; the image is one of its
# queries. Run it on a quiet machine: every figure depends on the CPU.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
workers=${1:-2}
connections=${2:-8}
seconds=${3:-20}
queue=${4:-32}
command -v wrk >/dev/null || { echo "wrk missing: apt-get install wrk" >&2; exit 1; }
load_map
tmp=$(mktemp -d)
trap 'stop_server; rm -rf "$tmp"' EXIT
server_config "$workers" "$queue" >"$tmp/config.toml"
start_server "$tmp/config.toml" "$tmp/server.log"
wrk_post_script "$tmp/post.lua" "$DATASET/images/50.jpg"
before=$(server_rss_kib)
wrk -t 1 -c "$connections" -d "${seconds}s" --latency -s "$tmp/post.lua" "http://$SERVER_ADDR/localize" >"$tmp/wrk.txt"
after=$(server_rss_kib)
rps=$(awk '/Requests\/sec/ {print $2}' "$tmp/wrk.txt")
total=$(awk '/requests in/ {print $1}' "$tmp/wrk.txt")
refused=$(awk '/Non-2xx/ {print $NF}' "$tmp/wrk.txt")
p50=$(awk '$1=="50%" {print $2}' "$tmp/wrk.txt")
p99=$(awk '$1=="99%" {print $2}' "$tmp/wrk.txt")
echo "workers=$workers connections=$connections seconds=$seconds queue=$queue"
echo "requests=$total refused_non_2xx=${refused:-0} requests_per_s=$rps latency_p50=$p50 latency_p99=$p99"
echo "server_rss_kib_before=$before server_rss_kib_after=$after"
