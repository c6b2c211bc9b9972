#!/usr/bin/env bash
# An ORB pass before SIFT, measured: runs examples/orb_pass.rs on both
# shared datasets with the maps scripts/latency.sh uses (gardens-point
# K = 5000, rtabmap-loop K = 1000), vocabulary seeds 1 to 3 (each built on
# first use). For each it prints the full search's and the service's
# default's recall and median time, and for each setting of the pass the
# queries it answered, recall@1 and recall@5 against the full search and
# the median ratio of the request time to the full search's
# (docs/performance.md, "An ORB pass before SIFT").
#
#   scripts/orb-pass.sh [SEEDS]      (default "1 2 3")
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
seeds=${1:-1 2 3}
cargo build --release --example orb_pass >&2
for seed in $seeds; do
  gardens_map 5000 "$seed" >&2
  dir=$(map_dir data/gardens-5000 "$seed")
  ./target/release/examples/orb_pass ../shared/datasets/gardens-point "$dir/vocab.bowvoc" "$dir/map.bowmap"
done
for seed in $seeds; do
  load_map "$seed" >&2
  dir=$(map_dir data/load "$seed")
  ./target/release/examples/orb_pass "$DATASET" "$dir/vocab.bowvoc" "$dir/map.bowmap"
done
