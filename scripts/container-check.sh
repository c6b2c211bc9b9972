#!/usr/bin/env bash
# Build the service image from the Dockerfile and run it as its users would:
#
#   1. as the Dockerfile's header says, with a dataset mounted at
#      /datasets/gardens-point: the service bootstraps the default map into
#      /data/default, becomes ready, answers a query; the image's own
#      HEALTHCHECK command passes, and the engine running it reports the
#      container healthy; it runs as its own user; SIGTERM (`stop`)
#      ends it with exit status 0;
#   2. as the header's other example says: the map mounted at /data and
#      named by flags, no configuration file: ready, a query answered;
#   3. as deploy/kubernetes/base runs it: the ConfigMap's configuration
#      mounted read-only at /etc/bowloc, the map (the one step 1 built)
#      read-only at /maps, a read-only root filesystem, every capability
#      dropped, no privilege escalation, user and group 10001: ready, a
#      query answered, no warning or error in its log, exit 0 on SIGTERM.
#
#   scripts/container-check.sh
#
# Environment:
#   CONTAINER_ENGINE   docker or podman (default: docker when its daemon
#                      answers, else podman)
#   IMAGE              the image's name (default localhost/bowloc:check)
#   SKIP_BUILD=1       check IMAGE as it is, without building it
#   BUILD_FLAGS        extra flags for `build` (e.g. `--pull=never` where
#                      the base images are local, `--isolation chroot` for
#                      podman inside a container)
#   DATASET            the gardens-point folder (default
#                      ../shared/datasets/gardens-point)
#
# Prints a line per check (`ok` or `FAIL`) and exits non-zero when any
# failed. Takes as long as the image's build: the first one compiles every
# dependency (about half an hour on 2 cores).
set -uo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)

if [ -z "${CONTAINER_ENGINE:-}" ]; then
  if command -v docker >/dev/null && docker info >/dev/null 2>&1; then
    CONTAINER_ENGINE=docker
  elif command -v podman >/dev/null; then
    CONTAINER_ENGINE=podman
  else
    echo "neither a Docker daemon nor podman here (Debian: apt-get install podman)" >&2
    exit 2
  fi
fi
engine=$CONTAINER_ENGINE
IMAGE=${IMAGE:-localhost/bowloc:check}
DATASET=$(cd "${DATASET:-../shared/datasets/gardens-point}" && pwd) || {
  echo "no dataset folder: set DATASET" >&2
  exit 2
}
QUERY=$DATASET/day_right/Image100.jpg

failed=0
ok() { echo "ok    $*"; }
fail() { echo "FAIL  $*"; failed=1; }
check() { # check DESCRIPTION COMMAND…: ok when the command succeeds
  local what=$1
  shift
  if "$@"; then ok "$what"; else fail "$what"; fi
}

tmp=$(mktemp -d)
containers=()
cleanup() {
  for c in "${containers[@]}"; do "$engine" rm -f "$c" >/dev/null 2>&1; done
  rm -rf "$tmp"
}
trap cleanup EXIT

free_port() {
  python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}

wait_ready() { # wait_ready PORT CONTAINER SECONDS: /readyz answers 200
  local port=$1 ctr=$2 seconds=$3 t
  for ((t = 0; t < seconds * 2; t++)); do
    [ "$(curl -s -o /dev/null -w '%{http_code}' "http://127.0.0.1:$port/readyz")" = 200 ] && return 0
    [ "$("$engine" inspect -f '{{.State.Running}}' "$ctr" 2>/dev/null)" = true ] || return 1
    sleep 0.5
  done
  return 1
}

localize() { # localize PORT: the top candidate's name of a real query
  curl -s --data-binary @"$QUERY" -H 'Content-Type: image/jpeg' \
    "http://127.0.0.1:$port/localize?top_n=3" -o "$tmp/answer.json" -w '%{http_code}' >"$tmp/status"
  [ "$(cat "$tmp/status")" = 200 ] && jq -e '.candidates | length > 0' "$tmp/answer.json" >/dev/null
}

stop_cleanly() { # stop_cleanly CONTAINER: SIGTERM, then its exit status is 0
  local ctr=$1 status
  "$engine" stop -t 30 "$ctr" >/dev/null 2>>"$tmp/engine.log"
  status=$("$engine" inspect -f '{{.State.ExitCode}}' "$ctr")
  [ "$status" = 0 ] || { echo "      exit status $status"; return 1; }
}

if [ "${SKIP_BUILD:-}" != 1 ]; then
  start=$(date +%s)
  # podman builds OCI images unless told otherwise, and an OCI image has no
  # HEALTHCHECK: build Docker's format, as docker does
  format=()
  [ "$engine" = podman ] && format=(--format docker)
  # shellcheck disable=SC2086
  if "$engine" build "${format[@]}" ${BUILD_FLAGS:-} -t "$IMAGE" . >"$tmp/build.log" 2>&1; then
    ok "$engine build -t $IMAGE . ($(($(date +%s) - start)) s)"
  else
    tail -30 "$tmp/build.log"
    fail "$engine build -t $IMAGE ."
    exit 1
  fi
fi

size=$("$engine" image inspect -f '{{.Size}}' "$IMAGE")
ok "image $IMAGE: $((size / 1000000)) MB"
version=$("$engine" run --rm "$IMAGE" --version 2>/dev/null)
check "the image runs the binary: $version" grep -q '^bowloc ' <<<"$version"
libraries() { # ldd ran in the image, found OpenCV and nothing missing
  "$engine" run --rm --entrypoint ldd "$IMAGE" /usr/local/bin/bowloc >"$tmp/ldd" 2>&1 &&
    grep -q libopencv_core "$tmp/ldd" && ! grep 'not found' "$tmp/ldd"
}
if libraries; then
  ok "every library the binary links is in the image ($(grep -c '=>' "$tmp/ldd") of them)"
else
  fail "the libraries the binary links, in the image: $(head -c 300 "$tmp/ldd")"
fi
healthcheck=$("$engine" inspect -f '{{json .Config.Healthcheck}}' "$IMAGE" 2>/dev/null)
[ "$healthcheck" = null ] || [ -z "$healthcheck" ] &&
  healthcheck=$("$engine" inspect -f '{{json .HealthCheck}}' "$IMAGE" 2>/dev/null)
check "the image declares its HEALTHCHECK ($healthcheck)" grep -q 'healthcheck' <<<"$healthcheck"

run_ready() { # run_ready NAME SECONDS WHAT RUN-ARGUMENTS…: run detached,
  # published on a free loopback port (sets ctr and port), wait for /readyz
  local name=$1 seconds=$2 what=$3 start
  shift 3
  port=$(free_port)
  ctr=bowloc-check-$name-$$
  containers+=("$ctr")
  start=$(date +%s)
  "$engine" run -d --name "$ctr" -p "127.0.0.1:$port:8080" "$@" >/dev/null 2>>"$tmp/engine.log"
  if wait_ready "$port" "$ctr" "$seconds"; then
    ok "$what ($(($(date +%s) - start)) s)"
  else
    "$engine" logs "$ctr" 2>&1 | tail -20
    tail -5 "$tmp/engine.log"
    fail "$what"
    return 1
  fi
}

answers_query() {
  if localize "$port"; then
    ok "answers a query (top candidate $(jq -r '.candidates[0].name' "$tmp/answer.json"))"
  else
    fail "a query: $(cat "$tmp/status") $(head -c 300 "$tmp/answer.json")"
  fi
}

# 1. The Dockerfile's own example: bootstrap from a mounted dataset.
run_ready bootstrap 600 "bootstrapped the default map from the mounted dataset and became ready" \
  -v "$DATASET:/datasets/gardens-point:ro" "$IMAGE" || exit 1
answers_query
check "the HEALTHCHECK command passes inside the container" \
  "$engine" exec "$ctr" bowloc healthcheck --address 127.0.0.1:8080 --path /readyz
engine_health() { # the engine itself runs the image's HEALTHCHECK: healthy
  if [ "$engine" = podman ]; then
    # podman runs it from systemd timers, which a machine without systemd
    # lacks: run it once as the timer would
    podman healthcheck run "$ctr" >/dev/null 2>>"$tmp/engine.log" || return 1
  fi
  local t status
  # docker runs it every 15 s (the image's interval) from the start
  for ((t = 0; t < 60; t++)); do
    status=$("$engine" inspect -f '{{.State.Health.Status}}' "$ctr" 2>/dev/null)
    [ "$status" = healthy ] && return 0
    sleep 1
  done
  echo "      health status: $status"
  return 1
}
check "$engine reports the container healthy (its HEALTHCHECK run by the engine)" engine_health
uid=$("$engine" exec "$ctr" id -u)
check "runs as its own user (uid $uid)" test "$uid" = 10001
"$engine" cp "$ctr:/data/default/vocab.bowvoc" "$tmp/vocab.bowvoc" &&
  "$engine" cp "$ctr:/data/default/map.bowmap" "$tmp/map.bowmap"
check "the bootstrapped files are in /data/default" test -s "$tmp/map.bowmap"
check "SIGTERM ends it with exit status 0" stop_cleanly "$ctr"

# 2. The Dockerfile header's other example: the map mounted at /data, no
# configuration file named.
chmod -R a+rX "$tmp"
if run_ready mounted 120 "ready with the map mounted at /data and named by flags" \
  -v "$tmp:/data:ro" "$IMAGE" serve --vocab /data/vocab.bowvoc --map /data/map.bowmap; then
  answers_query
  check "SIGTERM ends it with exit status 0" stop_cleanly "$ctr"
fi

# 3. As deploy/kubernetes/base runs it.
mkdir -p "$tmp/etc" "$tmp/maps"
mv "$tmp/vocab.bowvoc" "$tmp/map.bowmap" "$tmp/maps/"
chmod -R a+rX "$tmp"
# the ConfigMap's config.toml, its block de-indented
awk '/config.toml: \|/ {on = 1; next} on && /^[^ ]/ {on = 0} on {sub(/^    /, ""); print}' \
  deploy/kubernetes/base/configmap.yaml >"$tmp/etc/config.toml"
check "read the ConfigMap's configuration ($(wc -l <"$tmp/etc/config.toml") lines)" grep -q '^\[files\]' "$tmp/etc/config.toml"
if run_ready kubernetes 120 "ready with a read-only root filesystem, no capabilities, the map read-only at /maps" \
  --read-only --cap-drop ALL --security-opt no-new-privileges --user 10001:10001 \
  -v "$tmp/etc:/etc/bowloc:ro" -v "$tmp/maps:/maps:ro" \
  "$IMAGE" serve --config /etc/bowloc/config.toml; then
  answers_query
  check "SIGTERM ends it with exit status 0" stop_cleanly "$ctr"
  "$engine" logs "$ctr" >"$tmp/kubernetes.log" 2>&1
  warnings=$(grep -E '"level":"(WARN|ERROR)"' "$tmp/kubernetes.log" | head -5)
  check "no warning or error in its log${warnings:+: $warnings}" test -z "$warnings"
fi

exit "$failed"
