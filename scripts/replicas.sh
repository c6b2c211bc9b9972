#!/usr/bin/env bash
# Replicas behind a load balancer, one killed mid-run: three `bowloc serve`
# on loopback ports behind Debian's haproxy (health checks on /readyz, an
# idempotent POST /localize retried on another replica when one fails), wrk
# posting a real query image through the balancer. In the middle phase one
# replica is killed with SIGKILL and restarted on the same port; the
# balancer takes it back once its /readyz answers 200 (haproxy's check).
#
#   scripts/replicas.sh [PHASE_SECONDS] [CONNECTIONS]     (default 10 s, 6)
#
# Prints, for each phase (before, during: kill and restart, after), the
# requests sent, answered (2xx) and failed (any other status or a socket
# error), and p50/p99 latency as wrk measured them; then when the killed
# replica answered /readyz again and when haproxy put it back in rotation,
# and the requests each replica served after it. Exits non-zero when any
# client request failed or the replica did not come back. The map is
# rtabmap-loop (K = 1000, data/load/), one worker per replica.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
phase=${1:-10}
connections=${2:-6}
command -v haproxy >/dev/null || { echo "haproxy missing: scripts/setup.sh installs it" >&2; exit 1; }
load_prepare
tmp=$TMP
haproxy_pid=""
replica_pids=()
cleanup() {
  [ -n "$haproxy_pid" ] && kill "$haproxy_pid" 2>/dev/null
  for p in "${replica_pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$tmp"
}
trap cleanup EXIT

# five free loopback ports: three replicas, the balancer, its statistics
read -r -a ports < <(python3 -c '
import socket
ss = [socket.socket() for _ in range(5)]
for s in ss: s.bind(("127.0.0.1", 0))
print(" ".join(str(s.getsockname()[1]) for s in ss))')
lb="127.0.0.1:${ports[3]}"
stats="127.0.0.1:${ports[4]}"
server_config 1 32 >"$tmp/config.toml"

# start_replica I: replica I on its port, waiting for /readyz
start_replica() {
  start_server "$tmp/config.toml" "$tmp/replica$1.log" --listen "127.0.0.1:${ports[$1]}"
  replica_pids[$1]=$SERVER_PID
  SERVER_PID=""
}
for i in 0 1 2; do start_replica "$i"; done

cat >"$tmp/haproxy.cfg" <<CFG
global
  maxconn 256
defaults
  mode http
  timeout connect 1s
  timeout client 30s
  timeout server 30s
  # an idempotent request is retried, on another replica, when its replica
  # refuses the connection, closes it without an answer or answers 5xx
  retries 3
  retry-on all-retryable-errors
  option redispatch 1
  option http-buffer-request
frontend localize
  bind $lb
  default_backend replicas
backend replicas
  balance leastconn
  option httpchk GET /readyz
  http-check expect status 200
  default-server check inter 250ms fall 2 rise 1
  server r0 127.0.0.1:${ports[0]}
  server r1 127.0.0.1:${ports[1]}
  server r2 127.0.0.1:${ports[2]}
frontend stats
  bind $stats
  stats enable
  stats uri /stats
CFG
haproxy -f "$tmp/haproxy.cfg" -db >"$tmp/haproxy.log" 2>&1 &
haproxy_pid=$!
for _ in $(seq 50); do
  curl -sf "http://$lb/readyz" >/dev/null && break
  sleep 0.1
done

# wrk's own counts: every request it sent either answered 2xx or failed
cat >>"$tmp/post.lua" <<'LUA'
done = function(summary, latency, requests)
  local e = summary.errors
  local unanswered = e.connect + e.read + e.write + e.timeout
  io.write(string.format(
    "sent=%d answered=%d failed=%d (non-2xx %d, connect %d, read %d, write %d, timeout %d) p50=%.1fms p99=%.1fms\n",
    summary.requests + unanswered, summary.requests - e.status, e.status + unanswered,
    e.status, e.connect, e.read, e.write, e.timeout,
    latency:percentile(50) / 1000, latency:percentile(99) / 1000))
end
LUA
# run_phase NAME: one wrk run through the balancer, its counts in $tmp/NAME.txt
run_phase() {
  wrk -t 1 -c "$connections" -d "${phase}s" --timeout 10s -s "$tmp/post.lua" "http://$lb/localize" \
    | grep '^sent=' | sed "s/^/$1: /" >"$tmp/$1.txt"
}
# stat NAME FIELD: a column of the haproxy statistics CSV for server NAME
stat() {
  curl -s "http://$stats/stats;csv" | awk -F, -v s="$1" -v f="$2" '
    NR == 1 {for (i = 1; i <= NF; i++) if ($i == f || $i == "# " f) c = i}
    $1 == "replicas" && $2 == s {print $c}'
}

echo "replicas: 3 x bowloc serve (1 worker each) behind haproxy $(haproxy -v | awk 'NR == 1 {print $3}'), wrk $connections connections, ${phase} s a phase"
run_phase before
cat "$tmp/before.txt"
run_phase during &
wrk_pid=$!
sleep "$(awk -v p="$phase" 'BEGIN {print p * 0.2}')"
kill -KILL "${replica_pids[1]}"
wait "${replica_pids[1]}" 2>/dev/null || true
killed=$(date +%s.%N)
echo "during: replica r1 killed (SIGKILL) at $(awk -v p="$phase" 'BEGIN {print p * 0.2}') s"
sleep "$(awk -v p="$phase" 'BEGIN {print p * 0.3}')"
down=$(stat r1 status)
restarted=$(date +%s.%N)
start_replica 1
ready=$(date +%s.%N)
for _ in $(seq 100); do
  [ "$(stat r1 status)" = "UP" ] && break
  sleep 0.05
done
up=$(date +%s.%N)
awk -v k="$killed" -v r="$restarted" -v y="$ready" -v u="$up" -v d="$down" 'BEGIN {
  printf "during: haproxy saw r1 %s before the restart; restarted %.1f s after the kill, /readyz 200 after %.2f s, back in rotation (UP) %.2f s after the restart\n", d, r - k, y - r, u - r}'
wait "$wrk_pid"
cat "$tmp/during.txt"
before_after=$(for s in r0 r1 r2; do echo -n "$(stat "$s" stot) "; done)
run_phase after
cat "$tmp/after.txt"
after=$(for s in r0 r1 r2; do echo -n "$(stat "$s" stot) "; done)
echo "after: requests served per replica in the after phase: $(awk -v a="$before_after" -v b="$after" 'BEGIN {
  split(a, x, " "); split(b, y, " "); printf "r0 %d, r1 %d, r2 %d", y[1] - x[1], y[2] - x[2], y[3] - x[3]}')"
echo "haproxy: r1 $(stat r1 status), $(stat BACKEND wretr) requests retried, $(stat BACKEND wredis) redispatched to another replica"
failed=$(cat "$tmp"/{before,during,after}.txt | grep -o 'failed=[0-9]*' | cut -d= -f2 | awk '{n += $1} END {print n + 0}')
[ "$(stat r1 status)" = "UP" ] || { echo "r1 is not back in rotation" >&2; exit 1; }
[ "$failed" = 0 ] || { echo "$failed client requests failed" >&2; exit 1; }
echo "zero failed client requests, before, during and after the kill"
