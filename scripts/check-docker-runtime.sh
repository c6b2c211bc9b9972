#!/usr/bin/env bash
# Check that the Dockerfile's runtime stage installs what the binary needs:
# every shared library `ldd` lists for the binary must belong (dpkg -S, on
# this Debian bookworm machine) to a package that the runtime stage's
# packages bring in (themselves or through their dependencies), and the
# OpenCV packages listed must be exactly those of the OpenCV libraries the
# binary links directly.
#
# usage: scripts/check-docker-runtime.sh [path/to/bowloc] [path/to/Dockerfile]
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
BIN="${1:-$ROOT/target/release/bowloc}"
DOCKERFILE="${2:-$ROOT/Dockerfile}"

# The packages of the runtime stage: the `apt-get install` of the stage that
# starts FROM debian:bookworm-slim (backslash continuations joined).
runtime_packages=$(
  awk '/^FROM /{ runtime = ($2 ~ /^debian:bookworm-slim/) } runtime' "$DOCKERFILE" |
    sed -e ':a' -e '/\\$/N; s/\\\n//; ta' |
    grep -o 'apt-get install[^&;]*' |
    tr ' ' '\n' | grep -Ev '^(apt-get|install|-.*|)$' | sort -u
)
[ -n "$runtime_packages" ] || { echo "no apt-get install found in the runtime stage of $DOCKERFILE"; exit 1; }
echo "runtime stage installs: $(echo $runtime_packages)"

# Everything those packages bring in, as installed here.
# shellcheck disable=SC2086
provided=$(
  apt-cache depends --recurse --installed --no-recommends --no-suggests \
    --no-conflicts --no-breaks --no-replaces --no-enhances $runtime_packages 2>/dev/null |
    grep -v '^ ' | sed 's/:.*//' | sort -u
)

owner() { # the package owning a library path (trying the /usr-merged twin)
  local path=$1 real alt
  real=$(readlink -f "$path")
  for p in "$path" "$real" "${path#/usr}" "/usr$path" "${real#/usr}" "/usr$real"; do
    alt=$(dpkg -S "$p" 2>/dev/null | head -1 | cut -d: -f1) && [ -n "$alt" ] && { echo "$alt"; return 0; }
  done
  return 1
}

status=0
libraries=$(ldd "$BIN" | awk '/=>/ { print $3 } /^\s*\// { print $1 }' | grep '^/' | sort -u)
count=0
for lib in $libraries; do
  count=$((count + 1))
  pkg=$(owner "$lib") || { echo "MISSING: $lib belongs to no package"; status=1; continue; }
  if ! grep -qx "$pkg" <<<"$provided"; then
    echo "MISSING: $lib (package $pkg) is not brought in by the runtime stage"
    status=1
  fi
done

# The OpenCV packages must match the OpenCV libraries linked directly.
needed_opencv=$(
  readelf -d "$BIN" | grep -o 'libopencv_[a-z0-9]*\.so\.[0-9]*' | sort -u |
    while read -r soname; do owner "$(ldd "$BIN" | awk -v s="$soname" '$1 == s { print $3 }')"; done | sort -u
)
listed_opencv=$(grep '^libopencv' <<<"$runtime_packages" | sort -u || true)
if [ "$needed_opencv" != "$listed_opencv" ]; then
  echo "OpenCV packages differ: the binary links $(echo $needed_opencv), the runtime stage lists $(echo $listed_opencv)"
  status=1
fi

if [ "$status" -eq 0 ]; then
  echo "ok: the runtime stage provides all $count libraries the binary loads"
fi
exit "$status"
