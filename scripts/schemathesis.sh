#!/usr/bin/env bash
# Property-based tests of the HTTP API with schemathesis: a real
# `bowloc serve` on loopback, requests generated from its own
# /openapi.json, and a failure on any 5xx answer or any answer that does not
# match the document (status, content type, headers, body schema), or on
# schema-invalid requests that are accepted, or on any request the server
# took over 10 s to answer. Two checks are left out: max_response_time, the
# time the client measured, which counts the fuzzer's own pauses and the
# host's (the server's log times every request instead: the slowest are
# printed, and one over the limit fails the run); and
# positive_data_acceptance (every schema-valid request answered 2xx). The body
# is bytes that only a decoder can judge, and the rule parameters depend on
# each other (one of threshold, delta and fraction; its range depends on the
# rule), which a schema of query parameters cannot express: such requests are
# rightly 400 or 422.
#
#   scripts/schemathesis.sh [SECONDS]     (default 600; CI runs 90)
#
# schemathesis (PyPI) is installed into target/venv on first use. The map is
# rtabmap-loop (K = 1000), built into data/load/ on first use; the server
# serves a copy of it with a write token, which every request sends, so the
# write endpoints (PUT and DELETE /images/{id}, POST /map/compact) are
# exercised too (schemathesis also checks that they refuse a request without
# it). Its health check `filter_too_much` is suppressed: the `{id}` path
# parameter is any string, and schemathesis filters out most of those it
# draws as unfit for a URL path, then stops the operation without it. The
# exit status is non-zero when schemathesis found anything.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
budget=${1:-600}
MAX_LATENCY_MS=10000
SCHEMATHESIS_VERSION=4.32.5
venv=target/venv
if ! "$venv/bin/schemathesis" --version 2>/dev/null | grep -q "$SCHEMATHESIS_VERSION"; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q "schemathesis==$SCHEMATHESIS_VERSION"
fi
# Every check schemathesis registers but positive_data_acceptance, read
# from its registry: `--checks all` would switch on max_response_time too,
# which is not a registered check and cannot be excluded by name.
CHECKS=$("$venv/bin/python" -c '
import schemathesis.specs.openapi.checks
from schemathesis.checks import CHECKS
print(",".join(sorted(set(CHECKS.get_all_names()) - {"positive_data_acceptance"})))')
echo "checks: $CHECKS"
load_map
tmp=$(mktemp -d)
trap 'stop_server; rm -rf "$tmp"' EXIT
cp data/load/vocab.bowvoc data/load/map.bowmap "$tmp/"
token=schemathesis-write-token-0123456789
# the copy is the load map, so its images serve the thumbnails: links from
# /localize's candidates reach GET /images/{id}/thumbnail's 200 answers
server_config 2 32 "$tmp" "$(printf '[auth]\nwrite_token = "%s"' "$token")" "$DATASET" >"$tmp/config.toml"
start_server "$tmp/config.toml" "$tmp/server.log"
run() {
  local status=0
  "$venv/bin/schemathesis" run "http://$SERVER_ADDR/openapi.json" \
    --checks "$CHECKS" \
    --max-time "$budget" \
    --request-timeout 30 \
    --workers 2 \
    --header "Authorization: Bearer $token" \
    --suppress-health-check=filter_too_much \
    --no-color >"$tmp/run.out" 2>&1 || status=$?
  cat "$tmp/run.out"
  return "$status"
}
# Whether the last run failed only because Hypothesis's own engine crashed:
# no check failed, every error is a runtime error, and the traceback is in
# Hypothesis's internals. That says nothing about the API, so the run is
# repeated once (with a new seed); a failed check never is.
engine_crash_only() {
  ! grep -q '^Failures:' "$tmp/run.out" &&
    grep -q 'site-packages/hypothesis/internal/' "$tmp/run.out" &&
    awk '/^Errors:/ {on = 1; next} on && NF == 0 {on = 0} on && !/Runtime Error/ {bad = 1}
      END {exit bad}' "$tmp/run.out"
}
status=0
run || status=$?
if [ "$status" != 0 ] && engine_crash_only; then
  echo "schemathesis: Hypothesis's engine crashed (no check failed); running once more"
  status=0
  run || status=$?
fi
grep -E 'panicked|ERROR' "$tmp/server.log" && status=1
# The slowest requests as the server timed them (arrival to answer).
slowest=$(grep -o 'method=[A-Z]* route="[^"]*" status=[0-9]* latency_ms=[0-9.]*' "$tmp/server.log" |
  sort -t= -k5 -g | tail -5)
echo "slowest requests (server's log):"
echo "$slowest"
if echo "$slowest" | awk -F'latency_ms=' -v limit="$MAX_LATENCY_MS" '$2 > limit {bad = 1} END {exit !bad}'; then
  echo "a request took over $MAX_LATENCY_MS ms"
  status=1
fi
echo "schemathesis exit status: $status"
exit "$status"
