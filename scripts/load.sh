#!/usr/bin/env bash
# Throughput of a real `bowloc serve` on loopback against its worker count:
# wrk posts one rtabmap-loop query (512×384) for SECONDS s per run, the worker
# counts take turns (REPEATS rounds, so a slow spell of the machine falls on
# every count alike), and the medians over rounds and their ratio to the
# first count are printed. Each run reports requests per second, latency
# percentiles, refused (non-2xx) requests and the server's memory before and
# after. Bounded in time; every server is stopped at the end.
#
#   scripts/load.sh [WORKERS,...] [CONNECTIONS] [SECONDS] [REPEATS] [QUEUE]
#
# Defaults: workers 1,2; 4 connections; 15 s; 3 rounds; queue 32. The map is
# rtabmap-loop (K = 1000), built into data/load/ on first use. Run it on a
# quiet machine: every figure depends on the CPU.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
IFS=, read -ra worker_counts <<<"${1:-1,2}"
connections=${2:-4}
seconds=${3:-15}
repeats=${4:-3}
queue=${5:-32}
load_prepare
tmp=$TMP

# run WORKERS: one server, one wrk run; appends "WORKERS RPS" to $tmp/rps.
run() {
  server_config "$1" "$queue" >"$tmp/config.toml"
  start_server "$tmp/config.toml" "$tmp/server.log"
  local before after
  before=$(server_rss_kib)
  wrk -t 1 -c "$connections" -d "${seconds}s" --latency -s "$tmp/post.lua" \
    "http://$SERVER_ADDR/localize" >"$tmp/wrk.txt"
  after=$(server_rss_kib)
  stop_server
  local rps
  rps=$(awk '/Requests\/sec/ {print $2}' "$tmp/wrk.txt")
  echo "$1 $rps" >>"$tmp/rps"
  echo "workers=$1 requests=$(awk '/requests in/ {print $1}' "$tmp/wrk.txt")" \
    "refused_non_2xx=$(awk '/Non-2xx/ {n = $NF} END {print n + 0}' "$tmp/wrk.txt")" \
    "requests_per_s=$rps latency_p50=$(awk '$1 == "50%" {print $2}' "$tmp/wrk.txt")" \
    "latency_p99=$(awk '$1 == "99%" {print $2}' "$tmp/wrk.txt")" \
    "server_rss_kib_before=$before server_rss_kib_after=$after"
}

echo "connections=$connections seconds=$seconds rounds=$repeats queue=$queue"
for round in $(seq "$repeats"); do
  for w in "${worker_counts[@]}"; do
    echo -n "round $round: "
    run "$w"
  done
done
median_rps() { awk -v w="$1" '$1 == w {print $2}' "$tmp/rps" | sort -g | awk '{v[NR] = $1} END {print v[int((NR + 1) / 2)]}'; }
base=$(median_rps "${worker_counts[0]}")
for w in "${worker_counts[@]}"; do
  m=$(median_rps "$w")
  echo "workers=$w median_requests_per_s=$m ratio_to_${worker_counts[0]}_workers=$(awk -v a="$m" -v b="$base" 'BEGIN {printf "%.2f", a / b}')"
done
