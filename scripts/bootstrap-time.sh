#!/usr/bin/env bash
# How long `make run` takes to become ready from a fresh clone (no data/):
# clones this repository's HEAD into a folder beside the repository (so that
# ../shared/datasets resolves), reuses this checkout's target/ to skip most
# of the compilation, runs `make run` on a free port, and prints each step
# /readyz reports and the seconds from "listening" to ready.
#
# usage: scripts/bootstrap-time.sh [CLONE-DIR]   (default: ../tmp-bootstrap)
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
CLONE="${1:-$ROOT/../tmp-bootstrap}"
[ -e "$CLONE" ] && { echo "$CLONE exists; remove it or name another folder" >&2; exit 1; }
git clone -q "$ROOT" "$CLONE"
[ -d "$ROOT/target" ] && cp -a "$ROOT/target" "$CLONE/target"
cd "$CLONE"
echo "machine: $(nproc) cores, $(lscpu | sed -n 's/^Model name: *//p')"
echo "load before: $(cut -d' ' -f1-3 /proc/loadavg)"
BOWLOC_SERVER__LISTEN=127.0.0.1:0 make run >make-run.log 2>&1 &
MAKE=$!
SERVER=""
cleanup() {
  [ -n "$SERVER" ] && kill -TERM "$SERVER" 2>/dev/null
  wait "$MAKE" 2>/dev/null || true
}
trap cleanup EXIT
port=""
while [ -z "$port" ]; do
  sleep 0.5
  kill -0 "$MAKE" 2>/dev/null || { tail make-run.log; exit 1; }
  port=$(grep -o 'listening on http://127.0.0.1:[0-9]*' make-run.log | head -1 | sed 's/.*://' || true)
done
SERVER=$(pgrep -P "$MAKE" -f 'bowloc serve' | head -1)
t0=$(date +%s.%N)
last=""
while true; do
  status=$(curl -s -o readyz.json -w '%{http_code}' "http://127.0.0.1:$port/readyz")
  elapsed=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.1f", b - a }')
  [ "$status" = 200 ] && { echo "ready after $elapsed s"; break; }
  step=$(jq -r '.error.step // empty' readyz.json)
  kind=${step% [0-9]*/[0-9]*}
  [ "$kind" != "$last" ] && { echo "$elapsed s: $step"; last=$kind; }
  sleep 1
done
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"
grep -E 'bootstrap: (vocabulary|map) written' make-run.log | sed 's/\x1b\[[0-9;]*m//g'
