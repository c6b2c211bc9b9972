#!/usr/bin/env bash
# The full search's recall with the queries streamed in tiles against the
# queries extracted whole, read from the results.json that `bowloc eval`
# (scripts/eval-all.sh) wrote: mean ± std over the vocabulary seeds, in %.
#
#   scripts/tiling-check.sh data/eval/gardens-point-k5000/results.json
set -euo pipefail
jq -r '
  def pct(s): "\(s.mean * 1000 | round / 10) ± \(s.std * 1000 | round / 10)";
  def row(x): "\(x.label): recall@1 \(pct(x.recall_at_1)), recall@5 \(pct(x.recall_at_5))";
  (.settings[] | select(.label == "none") | row(.)),
  (.whole_image | row(.))' "$1"
