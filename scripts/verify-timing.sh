#!/usr/bin/env bash
# Median request time with and without geometric verification, measured in
# one run: `bowloc query` over every query of a dataset, in batches of 20
# images, each batch answered without and then with --verify (so both see the
# same machine load). Prints the medians of timings_ms.total and of
# timings_ms.verify (docs/performance.md).
# Usage: scripts/verify-timing.sh VOCAB MAP [DATASET] [extra query args...]
set -euo pipefail
cd "$(dirname "$0")/.."
B=./target/release/bowloc
VOCAB=$1
MAP=$2
D=${3:-../shared/datasets/gardens-point}
shift 3 || shift $#
command -v jq >/dev/null || { echo "jq is needed (scripts/setup.sh installs it)" >&2; exit 1; }
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
mapfile -t QUERIES < <(sed "s|^|$D/|" "$D/queries.txt")
for ((i = 0; i < ${#QUERIES[@]}; i += 20)); do
    batch=("${QUERIES[@]:i:20}")
    "$B" query --vocab "$VOCAB" --map "$MAP" --rule none --seed 1 "$@" "${batch[@]}" 2>/dev/null |
        jq -r '.[].timings_ms.total' >>"$TMP/without"
    "$B" query --vocab "$VOCAB" --map "$MAP" --rule none --seed 1 --verify "$@" "${batch[@]}" 2>/dev/null |
        jq -r '.[].timings_ms | "\(.total) \(.verify)"' >>"$TMP/with"
done
median() { sort -g | awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
without=$(median <"$TMP/without")
with=$(cut -d' ' -f1 "$TMP/with" | median)
verify=$(cut -d' ' -f2 "$TMP/with" | median)
echo "queries: $(wc -l <"$TMP/without")"
echo "median total without verification: $without ms"
echo "median total with verification:    $with ms"
echo "median verification time:          $verify ms"
awk -v a="$without" -v b="$with" 'BEGIN { printf "median request time added: %+.1f %%\n", 100 * (b - a) / a }'
