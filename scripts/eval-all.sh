#!/usr/bin/env bash
# Regenerate the evaluation behind docs/results.md on this machine, in one
# command: the README's eval command on both shared datasets (gardens-point
# at K = 5000, rtabmap-loop at K = 1000; 3 vocabulary seeds and 3 random
# feature orders each, queries streamed in 2x2 tiles as the service does,
# geometric verification on, plus the settings docs/results.md compares
# across maps), from empty caches unless --keep-cache. The full outputs land in
# data/eval/<dataset>-k<K>/; the tables, CSVs and figures are copied into
# docs/results/<dataset>/ (results.json, with every query's answers, stays in
# data/eval: it is large). docs/results.md pastes each results.md unchanged.
#
#   [EVAL_ARGS="--tile-order random"] scripts/eval-all.sh [--keep-cache]
#
# EVAL_ARGS: more `bowloc eval` options for both datasets (docs/results.md's
# dataset sections were made with `--tile-order random`).
#
# Every figure depends on the CPU (SIFT's output follows its instruction
# set): each results.md names the CPU, OpenCV's SIMD level and the
# descriptor checksums it was made with.
set -euo pipefail
cd "$(dirname "$0")/.."
keep_cache=no
case "${1:-}" in
  --keep-cache) keep_cache=yes ;;
  "") ;;
  *) echo "usage: scripts/eval-all.sh [--keep-cache]" >&2; exit 2 ;;
esac
cargo build --release
B=./target/release/bowloc
D=../shared/datasets
# settings run besides the grids, to see whether one carries over between maps
# (the service's default, place-z 2.25 with its verified stop, among them)
sets=(--set place-z=2@20 --set place-z=2.25+verified=12@20 --set peak-mean=1.6@20
      --set relative=2.5@100 --set verified=8 --set verified=12)
for run in gardens-point:5000 rtabmap-loop:1000; do
  name=${run%%:*}
  words=${run##*:}
  out=data/eval/$name-k$words
  if [ "$keep_cache" = no ]; then
    rm -rf "data/eval-cache/$name" "$out"
  fi
  /usr/bin/time -f "$name: wall %e s" \
    nice $B eval --dataset "$D/$name" --words "$words" --runs 3 --vocab-seeds 3 \
      --verify "${sets[@]}" ${EVAL_ARGS:-} --out "$out"
  mkdir -p "docs/results/$name"
  rm -f "docs/results/$name"/*
  cp "$out"/results.md "$out"/*.csv "$out"/*.png "$out"/*.svg "docs/results/$name/"
done
echo "docs/results/{gardens-point,rtabmap-loop} regenerated; paste their results.md into docs/results.md"
