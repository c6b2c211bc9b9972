#!/usr/bin/env bash
# Install the system packages bowloc needs on Debian bookworm (idempotent:
# does nothing when they are already there).
set -euo pipefail
# fonts-dejavu-core: the TrueType font `bowloc eval` draws its plots' text with.
# python3-venv: scripts/schemathesis.sh installs schemathesis into a virtualenv.
# wrk: the load scripts (scripts/load.sh, scripts/overload.sh, scripts/replicas.sh).
# haproxy: the load balancer in front of the replicas of scripts/replicas.sh.
# pkg-config: how the `opencv` crate finds OpenCV's headers and libraries.
packages=(libopencv-dev pkg-config clang libclang-dev curl jq make ca-certificates fonts-dejavu-core
  python3 python3-venv wrk haproxy)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}" >&2
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
