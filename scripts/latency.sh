#!/usr/bin/env bash
# Where a /localize request's time goes, measured from the client: one
# request at a time against a live `bowloc serve` on loopback (default rule
# and configuration), comparing curl's total time with the SIFT extraction
# time the answer reports. Prints medians and the share of the request that
# is not SIFT extraction (and how many answers were geometrically verified,
# as the configuration has it by default). Then, in the same run, each query
# twice in turn:
# the full search on the whole image (rule=none&tiles=1x1, what streaming and
# stopping save against) and the default configuration (streaming
# extraction, default rule): both medians, their ratio and the median of the
# per-query ratios.
#
#   [LATENCY_DATASET=rtabmap-loop] [LATENCY_SEEDS="1 2 3"] scripts/latency.sh [EVERY] [RULE-QUERY]
#
# LATENCY_DATASET: gardens-point (default; K = 5000 map, 960×540 queries) or
# rtabmap-loop (K = 1000 map, 512×384 queries), or either with its map and
# queries swapped: gardens-point-reversed, rtabmap-loop-reversed
# (scripts/reversed-datasets.sh, made on first use). EVERY: use every EVERY-th
# query (default 10 for gardens-point: 20 images; 1 for rtabmap-loop: 44),
# each sent 3 times. RULE-QUERY: extra query string, e.g. "rule=none".
# LATENCY_SEEDS: the vocabulary seeds to build a map with and measure, one
# server after the other (default 1): where a rule stops depends on the
# vocabulary drawn, so the comparison is printed for each and the worst named.
# The breakdown is printed for the first seed's map.
# LATENCY_PLAN: the configured extraction plan (search.tiles), e.g.
# "2x2+24,auto"; default the configuration's default.
# LATENCY_SEQUENCE=1: the default's requests are the frames of a sequence
# (`sequence=…&frame=N`, N the query's line; one sequence per pass), so the
# sequence filter's stop (`sequence.rule`) decides where they stop; the full
# search is sent alone, as before.
# LATENCY_ORB_PASS: the ORB pass looks at each of the default's requests
# first, as the configuration has it by default (each map's ORB side built
# beside it with `bowloc map orb-pass`, afresh each run); the comparison says
# how many it answered. LATENCY_ORB_PASS=0 turns it off ([orb_pass]
# enabled = false): the default without the pass.
# The comparison also prints recall@1 and recall@5 of the full search's and
# the default's answers against the dataset's ground truth.
# The server learns the coarse pass (`tiles = "…,auto"`) from the requests
# it answers, as it does in service; each server answers the breakdown's
# requests before the comparison (the first 32 are the learned plan's
# trials), so every seed is compared after them.
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/lib/server.sh
name=${LATENCY_DATASET:-gardens-point}
# the ORB pass: on unless LATENCY_ORB_PASS=0 (orb_on empty when off)
orb_on=true
[ "${LATENCY_ORB_PASS:-1}" = 0 ] && orb_on=
seeds=${LATENCY_SEEDS:-1}
case $name in
  gardens-point | gardens-point-reversed) default_every=10 words=5000 ;;
  rtabmap-loop | rtabmap-loop-reversed) default_every=1 words=1000 ;;
  *) echo "LATENCY_DATASET: gardens-point, rtabmap-loop or either with -reversed, not $name" >&2; exit 2 ;;
esac
# the dataset's folder, and where its maps are kept (named as built)
case $name in
  gardens-point) src=../shared/datasets/$name base=data/gardens-5000 map_name=$name ;;
  rtabmap-loop) src=$DATASET base=data/load map_name= ;;
  *)
    src=data/datasets/$name base=data/$name-$words map_name=$name
    [ -f "$src/map.txt" ] || scripts/reversed-datasets.sh >&2 ;;
esac
# the map for vocabulary seed $1, built if missing; prints its folder
map_for() {
  dataset_map "$src" "$words" "$1" "$base" "$map_name" >&2
  local dir
  dir=$(map_dir "$base" "$1")
  # the side is built afresh, so that it is the current default's
  if [ -n "$orb_on" ]; then
    "$BOWLOC_BIN" map orb-pass --vocab "$dir/vocab.bowvoc" --map "$dir/map.bowmap" \
      --images "$src/map.txt" >&2
  fi
  echo "$dir"
}
every=${1:-$default_every}
extra=${2:-}
tmp=$(mktemp -d)
trap 'stop_server; rm -rf "$tmp"' EXIT
plan=${LATENCY_PLAN:+[search]
tiles = \"$LATENCY_PLAN\"}
orb="[orb_pass]
enabled = ${orb_on:-false}"
col() { cut -f"$1" "$tmp/rows" | median; }
# "LINE PATH" of each query used
queries() { awk -v e="$every" 'NR % e == 1 || e == 1 {print NR, $0}' $src/queries.txt; }
# the default's extra query string for query line $1 of pass $2 (seed $3)
asked() {
  local q=$extra
  if [ -n "${LATENCY_SEQUENCE:-}" ]; then
    q="${q:+$q&}sequence=latency-$3-$2&frame=$1"
  fi
  echo "${q:+&$q}"
}

# Where the default configuration's request time goes (one map).
breakdown() {
  : >"$tmp/rows"
  for pass in 1 2 3; do
    queries | while read -r n q; do
      client=$(curl -s -o "$tmp/answer.json" -w '%{time_total}' -H 'Content-Type: image/jpeg' \
        --data-binary @"$src/$q" "http://$SERVER_ADDR/localize?seed=$pass$(asked "$n" "$pass" breakdown)")
      jq -r --arg c "$client" '[($c | tonumber) * 1000, .timings_ms.decode, .timings_ms.extract,
        .timings_ms.quantize, .timings_ms.vote, .timings_ms.total, .features.fraction,
        (.timings_ms.verify // 0), (if .verified == null then "no" else "yes" end),
        (.timings_ms.orb_pass // 0)] | @tsv' \
        "$tmp/answer.json" >>"$tmp/rows"
    done
  done
  local share
  share=$(awk -F'\t' '{print 100 * ($1 - $3) / $1}' "$tmp/rows" | median)
  echo "dataset=$name requests=$(wc -l <"$tmp/rows") rule=$(jq -r '.rule.name + " " + (.rule.value | tostring) + (if .rule.or_verified then " or verified \(.rule.or_verified)" else "" end)' "$tmp/answer.json")"
  echo "median_ms request=$(col 1) decode=$(col 2) extract=$(col 3) quantize=$(col 4) vote=$(col 5) verify=$(col 8)${orb_on:+ orb_pass=$(col 10)} server_total=$(col 6) fraction_used=$(col 7)"
  echo "verified (geometric verification ran): $(cut -f9 "$tmp/rows" | grep -c yes) of $(wc -l <"$tmp/rows") requests"
  echo "median share of a request that is not SIFT extraction: ${share}%"
}

# Each query twice in turn, whole-image full search and the default; prints
# the comparison and appends "seed ratio-of-medians per-query-ratio" to
# $tmp/ratios.
compare() {
  : >"$tmp/pairs"
  for pass in 1 2 3; do
    queries | while read -r n q; do
      full=$(curl -s -o "$tmp/full.json" -w '%{time_total}' -H 'Content-Type: image/jpeg' \
        --data-binary @"$src/$q" "http://$SERVER_ADDR/localize?seed=$pass&rule=none&tiles=1x1")
      default=$(curl -s -o "$tmp/answer.json" -w '%{time_total}' -H 'Content-Type: image/jpeg' \
        --data-binary @"$src/$q" "http://$SERVER_ADDR/localize?seed=$pass$(asked "$n" "$pass" "$1")")
      tiles=$(jq -r '"\(.tiles.extracted)/\(.tiles.total)\t\(.tiles.grid)\t\(.stop.kind)"' "$tmp/answer.json")
      top5() { jq -r '[.candidates[:5][].name] | join(",")' "$1"; }
      printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$full" "$default" "$tiles" "$q" \
        "$(top5 "$tmp/full.json")" "$(top5 "$tmp/answer.json")" >>"$tmp/pairs"
    done
  done
  local full_ms default_ms per_query tiles coarse ratio
  full_ms=$(cut -f1 "$tmp/pairs" | median | awk '{print $1 * 1000}')
  default_ms=$(cut -f2 "$tmp/pairs" | median | awk '{print $1 * 1000}')
  per_query=$(awk -F'\t' '{print $2 / $1}' "$tmp/pairs" | median)
  tiles=$(awk -F'\t' '{split($3, t, "/"); s += t[1] / t[2]} END {printf "%.3f", s / NR}' "$tmp/pairs")
  coarse=$(awk -F'\t' '$4 ~ /coarse/ {c++} END {printf "%d of %d", c, NR}' "$tmp/pairs")
  ratio=$(awk -v a="$default_ms" -v b="$full_ms" 'BEGIN {printf "%.3f", a / b}')
  echo "vocabulary seed $1: full search, whole image: median ${full_ms} ms; default${extra:+ ($extra)}${LATENCY_SEQUENCE:+ as the frames of a sequence}, streaming: median ${default_ms} ms"
  echo "vocabulary seed $1: ratio of medians $ratio; median per-query ratio ${per_query}; mean share of tiles extracted ${tiles}; coarse pass first in ${coarse} requests"
  # recall@N (%) of the answers in column $1 of the pairs
  recall() {
    awk -F'\t' -v col="$1" -v n="$2" 'NR == FNR {if (FNR > 1) {split($0, r, ","); ok[r[1] "," r[2]] = 1}; next}
      {split($col, c, ","); hit = 0; for (i = 1; i <= n && i in c; i++) if (($6 "," c[i]) in ok) hit = 1; h += hit}
      END {printf "%.1f", 100 * h / FNR}' "$src/ground_truth.csv" "$tmp/pairs"
  }
  local orb_answered
  orb_answered=$(awk -F'\t' '$5 == "orb-pass" {c++} END {printf "%d of %d", c, NR}' "$tmp/pairs")
  echo "vocabulary seed $1: recall@1 full search $(recall 7 1), default $(recall 8 1); recall@5 full search $(recall 7 5), default $(recall 8 5)${orb_on:+; answered by the ORB pass: $orb_answered}"
  echo "$1 $ratio $per_query" >>"$tmp/ratios"
}

: >"$tmp/ratios"
first=1
for seed in $seeds; do
  dir=$(map_for "$seed")
  server_config 1 4 "$dir" "$plan
$orb" >"$tmp/config.toml"
  start_server "$tmp/config.toml" "$tmp/server.log"
  # every server answers the breakdown's requests first (printed for the
  # first seed's), so a learned plan has made its trials before the
  # comparison on every seed alike
  if [ "$first" = 1 ]; then
    breakdown
    first=0
  else
    breakdown >/dev/null
  fi
  compare "$seed"
  stop_server
done
if [ "$(wc -l <"$tmp/ratios")" -gt 1 ]; then
  awk '{r = r sep $2; p = p sep $3; sep = " / "; if ($2 > w) {w = $2; ws = $1}}
    END {print "over vocabulary seeds " NR ": ratio of medians " r " (worst " w ", seed " ws "); median per-query ratio " p}' "$tmp/ratios"
fi
