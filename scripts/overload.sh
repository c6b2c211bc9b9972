#!/usr/bin/env bash
# Drive a real `bowloc serve` past its capacity on loopback and report what
# the overload behaviour promises: excess requests refused with 503 at once,
# accepted ones with a bounded latency, memory that does not grow with the
# burst. Bounded in time; the server is stopped at the end.
#
#   scripts/overload.sh [CONNECTIONS] [SECONDS] [WORKERS] [QUEUE]
#
# Defaults: 64 connections for 20 s against 2 workers and a queue of 4, so
# at most 6 requests are taken at once and the rest are refused. The map is
# rtabmap-loop (K = 1000, data/load/); the image is one of its queries.
# Steps:
#   1. warm-up: wrk with 2 connections for 5 s (no refusals expected), so the
#      memory figures compare a warm server with itself;
#   2. burst: wrk with CONNECTIONS connections for SECONDS s, while curl sends
#      a probe request every 50 ms and records its status and time;
#   3. figures: accepted and refused counts and the accepted requests'
#      latency percentiles from the server's request log (every request,
#      queueing included), the probes' times split by status, wrk's totals,
#      and the server's resident memory (VmRSS) after start-up, after the
#      warm-up and after the burst, with its peak (VmHWM).
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
connections=${1:-64}
seconds=${2:-20}
workers=${3:-2}
queue=${4:-4}
load_prepare
tmp=$TMP
server_config "$workers" "$queue" >"$tmp/config.toml"
start_server "$tmp/config.toml" "$tmp/server.log"
image=$LOAD_IMAGE
url="http://$SERVER_ADDR/localize"
rss_start=$(server_rss_kib)
wrk -t 1 -c 2 -d 5s -s "$tmp/post.lua" "$url" >"$tmp/warmup.txt"
rss_warm=$(server_rss_kib)
lines_before=$(wc -l <"$tmp/server.log")

# probes: one request every 50 ms during the burst
probe() {
  local end=$((SECONDS + seconds - 1))
  sleep 1 # let wrk fill the queue first
  while [ "$SECONDS" -lt "$end" ]; do
    curl -s -o /dev/null -w '%{http_code} %{time_total}\n' -H 'Content-Type: image/jpeg' \
      --data-binary @"$image" "$url" >>"$tmp/probes.txt" || true
    sleep 0.05
  done
}
probe &
probe_pid=$!
wrk -t 2 -c "$connections" -d "${seconds}s" --latency -s "$tmp/post.lua" "$url" >"$tmp/burst.txt"
wait "$probe_pid"
rss_after=$(server_rss_kib)
rss_peak=$(awk '/VmHWM/ {print $2}' "/proc/$SERVER_PID/status")

# The burst's requests as the server logged them (probes included).
tail -n +"$((lines_before + 1))" "$tmp/server.log" | grep 'route="/localize"' >"$tmp/burst.log" || true
latencies() { # latencies STATUS: sorted latencies in ms of that status
  grep "status=$1 " "$tmp/burst.log" | sed 's/.*latency_ms=\([0-9.e-]*\).*/\1/' | sort -g
}
pct() { # pct P < sorted numbers: the P-th percentile (nearest rank)
  awk -v p="$1" '{ v[NR] = $1 } END { if (NR == 0) { print "-"; exit } r = int((p / 100) * NR + 0.999999); if (r < 1) r = 1; printf "%.2f\n", v[r] }'
}
latencies 200 >"$tmp/ok.ms"
latencies 503 >"$tmp/refused.ms"
accepted=$(wc -l <"$tmp/ok.ms")
refused=$(wc -l <"$tmp/refused.ms")
other=$(grep -vcE 'status=(200|503) ' "$tmp/burst.log" || true)
probe_times() { # probe_times STATUS: sorted times in ms
  awk -v s="$1" '$1 == s { printf "%.1f\n", $2 * 1000 }' "$tmp/probes.txt" | sort -g
}
probe_times 200 >"$tmp/probe-ok.ms"
probe_times 503 >"$tmp/probe-refused.ms"
probes=$(grep -c . "$tmp/probes.txt" || true)

echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')"
echo "server: workers=$workers queue=$queue; wrk: connections=$connections seconds=$seconds on $url"
echo "wrk: $(awk '/requests in/ {print $1, "requests"}' "$tmp/burst.txt"), non-2xx $(awk '/Non-2xx/ {print $NF}' "$tmp/burst.txt"), requests/s $(awk '/Requests\/sec/ {print $2}' "$tmp/burst.txt"), latency of all p50 $(awk '$1=="50%" {print $2}' "$tmp/burst.txt") p99 $(awk '$1=="99%" {print $2}' "$tmp/burst.txt")"
echo "server log: accepted (200) $accepted, refused (503) $refused, other statuses $other"
echo "accepted latency ms (server): p50 $(pct 50 <"$tmp/ok.ms") p99 $(pct 99 <"$tmp/ok.ms") max $(pct 100 <"$tmp/ok.ms")"
echo "refused latency ms (server): p50 $(pct 50 <"$tmp/refused.ms") p99 $(pct 99 <"$tmp/refused.ms") max $(pct 100 <"$tmp/refused.ms")"
echo "probes (curl time_total, ms): $probes sent; 503: $(wc -l <"$tmp/probe-refused.ms") median $(pct 50 <"$tmp/probe-refused.ms") max $(pct 100 <"$tmp/probe-refused.ms"); 200: $(wc -l <"$tmp/probe-ok.ms") median $(pct 50 <"$tmp/probe-ok.ms") max $(pct 100 <"$tmp/probe-ok.ms")"
echo "server RSS KiB: start $rss_start, after warm-up $rss_warm, after burst $rss_after, peak $rss_peak"
