#!/usr/bin/env bash
# Fuzz the loading of vocabulary and map files with cargo-fuzz (libFuzzer,
# AddressSanitizer). Usage: scripts/fuzz.sh [SECONDS]   (default 60; CI uses a
# short budget, run longer by hand, e.g. scripts/fuzz.sh 3600).
# The seed corpus is a small real vocabulary and map built from rtabmap-loop.
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-60}
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz --locked
corpus=fuzz/corpus/load_files
mkdir -p "$corpus"
if [ ! -f "$corpus/seed.bowmap" ]; then
  cargo build --release
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' EXIT
  d=../shared/datasets/rtabmap-loop
  printf '%s\n' "$PWD/$d/images/1.jpg" "$PWD/$d/images/2.jpg" "$PWD/$d/images/3.jpg" > "$tmp/few.txt"
  ./target/release/bowloc --log warn vocab build --images "$tmp/few.txt" --words 8 --out "$corpus/seed.bowvoc"
  ./target/release/bowloc --log warn map build --vocab "$corpus/seed.bowvoc" --images "$tmp/few.txt" --out "$corpus/seed.bowmap"
fi
# cargo-fuzz needs nightly flags; the stable toolchain accepts them with RUSTC_BOOTSTRAP.
RUSTC_BOOTSTRAP=1 cargo fuzz run load_files "$corpus" -- -max_total_time="$secs" -rss_limit_mb=4096
