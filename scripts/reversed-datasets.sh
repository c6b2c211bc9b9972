#!/usr/bin/env bash
# Two more image sets to hold out, made from the shared ones without copying
# an image: each shared dataset with its map and queries swapped.
# gardens-point-reversed maps the walk on the right of the path (day_right)
# and queries the one on the left (day_left); rtabmap-loop-reversed maps the
# corridor's second pass (frames 41-84) and queries its first (1-40). The
# ground truth is the same pairs read the other way. Neither is a new place:
# the images are the shared ones, but the vocabulary (trained on the map
# images only) and the map are new, and every map image was a query before.
#
#   scripts/reversed-datasets.sh [OUT]      (default OUT: the project's data/datasets)
#
# Writes OUT/<name>-reversed/{map.txt,queries.txt,ground_truth.csv} and links
# the image folders, so `bowloc eval --dataset OUT/<name>-reversed` and
# LATENCY_DATASET=<name>-reversed scripts/latency.sh read them.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-$root/data/datasets}
shared=$(cd "$root/../shared/datasets" && pwd)
for name in gardens-point rtabmap-loop; do
  src=$shared/$name
  dst=$out/$name-reversed
  mkdir -p "$dst"
  # the image folders the lists name, linked
  cut -d/ -f1 "$src/map.txt" "$src/queries.txt" | sort -u | while read -r dir; do
    ln -sfn "$src/$dir" "$dst/$dir"
  done
  cat "$src/queries.txt" > "$dst/map.txt"
  cat "$src/map.txt" > "$dst/queries.txt"
  awk -F, 'NR == 1 {print "query,match"; next} {print $2 "," $1}' \
    "$src/ground_truth.csv" > "$dst/ground_truth.csv"
  echo "$dst: $(wc -l < "$dst/map.txt") map images, $(wc -l < "$dst/queries.txt") queries, $(( $(wc -l < "$dst/ground_truth.csv") - 1 )) pairs"
done
