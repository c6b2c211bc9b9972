#!/usr/bin/env bash
# Fuzz the loading of vocabulary and map files, the reading of a map's change
# log, and the decoding and extraction of uploaded images, with cargo-fuzz
# (libFuzzer, AddressSanitizer). Usage:
# scripts/fuzz.sh [SECONDS]   (default 60, split between the three targets:
# half to the files, a sixth to the log, a third to the images; CI uses a
# short budget, run longer by hand, e.g. scripts/fuzz.sh 3600).
# The seed corpus of the files is a small real vocabulary and map built from
# rtabmap-loop; that of the log, a log of one add and one removal written by
# `bowloc map add|remove` on that map; that of the images, a small image in
# each format the service decodes (fuzz/seeds/decode_image, written by
# fuzz/seeds/generate.py) and the curl suite's unusual images
# (tests/fixtures).
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
log_corpus=fuzz/corpus/change_log
mkdir -p "$log_corpus"
if [ ! -f "$log_corpus/seed.changes" ]; then
  cargo build --release
  tmp=$(mktemp -d)
  d=../shared/datasets/rtabmap-loop
  cp "$corpus/seed.bowmap" "$tmp/m.bowmap"
  ./target/release/bowloc --log warn map add --vocab "$corpus/seed.bowvoc" --map "$tmp/m.bowmap" \
    --id added "$d/images/4.jpg" >/dev/null
  ./target/release/bowloc --log warn map remove --map "$tmp/m.bowmap" --id added >/dev/null
  cp "$tmp/m.bowmap.changes" "$log_corpus/seed.changes"
  rm -rf "$tmp"
fi
# cargo-fuzz needs nightly flags; the stable toolchain accepts them with RUSTC_BOOTSTRAP.
image_corpus=fuzz/corpus/decode_image
mkdir -p "$image_corpus"
for seed in fuzz/seeds/decode_image/* tests/fixtures/*.jpg tests/fixtures/*.png tests/fixtures/*.gif; do
  [ -e "$image_corpus/${seed##*/}" ] || cp "$seed" "$image_corpus/"
done
files_secs=$(( secs / 2 ))
log_secs=$(( secs / 6 ))
image_secs=$(( secs - files_secs - log_secs ))
RUSTC_BOOTSTRAP=1 cargo fuzz run load_files "$corpus" -- -max_total_time="$files_secs" -rss_limit_mb=4096
RUSTC_BOOTSTRAP=1 cargo fuzz run change_log "$log_corpus" -- -max_total_time="$log_secs" -rss_limit_mb=4096
# The decoders report damaged inputs on stderr themselves: OpenCV's log
# (quiet at level ERROR), and lines no setting quiets — libjpeg's and
# libpng's warnings and imdecode's own, as fuzzing runs printed them. Those
# are dropped so that libFuzzer's report stays readable; the
# run's status is the fuzzer's.
decoder_noise='^(Corrupt JPEG data|Invalid SOS|libpng (error|warning)|imdecode_)'
RUSTC_BOOTSTRAP=1 OPENCV_LOG_LEVEL=ERROR cargo fuzz run decode_image "$image_corpus" -- \
  -max_total_time="$image_secs" -rss_limit_mb=4096 2>&1 | { grep -Ev "$decoder_noise" || true; }
