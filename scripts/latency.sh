#!/usr/bin/env bash
# Where a /localize request's time goes, measured from the client: one
# request at a time against a live `bowloc serve` on loopback (K = 5000 map of
# gardens-point, 960×540 query images, default rule), comparing curl's total
# time with the SIFT extraction time the answer reports. Prints medians and
# the share of the request that is not SIFT extraction.
#
#   scripts/latency.sh [EVERY] [RULE-QUERY]
#
# EVERY: use every EVERY-th query of gardens-point (default 10: 20 images,
# each sent 3 times). RULE-QUERY: extra query string, e.g. "rule=none".
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
every=${1:-10}
extra=${2:-}
gardens_map 5000
tmp=$(mktemp -d)
trap 'stop_server; rm -rf "$tmp"' EXIT
server_config 1 4 data/gardens-5000 >"$tmp/config.toml"
start_server "$tmp/config.toml" "$tmp/server.log"
src=../shared/datasets/gardens-point
: >"$tmp/rows"
for pass in 1 2 3; do
  awk -v e="$every" 'NR % e == 1' $src/queries.txt | while read -r q; do
    client=$(curl -s -o "$tmp/answer.json" -w '%{time_total}' -H 'Content-Type: image/jpeg' \
      --data-binary @"$src/$q" "http://$SERVER_ADDR/localize?seed=$pass${extra:+&$extra}")
    jq -r --arg c "$client" '[($c | tonumber) * 1000, .timings_ms.decode, .timings_ms.extract,
      .timings_ms.quantize, .timings_ms.vote, .timings_ms.total, .features.fraction] | @tsv' \
      "$tmp/answer.json" >>"$tmp/rows"
  done
done
median() { sort -g | awk '{v[NR] = $1} END {print v[int((NR + 1) / 2)]}'; }
col() { cut -f"$1" "$tmp/rows" | median; }
share=$(awk -F'\t' '{print 100 * ($1 - $3) / $1}' "$tmp/rows" | median)
echo "requests=$(wc -l <"$tmp/rows") rule=$(jq -r '.rule.name + " " + (.rule.value | tostring)' "$tmp/answer.json")"
echo "median_ms request=$(col 1) decode=$(col 2) extract=$(col 3) quantize=$(col 4) vote=$(col 5) server_total=$(col 6) fraction_used=$(col 7)"
echo "median share of a request that is not SIFT extraction: ${share}%"
