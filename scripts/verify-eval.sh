#!/usr/bin/env bash
# Geometric verification on the shared datasets: recall with and without
# verification over three vocabulary seeds, and the choice of model,
# estimator and top k (docs/results.md, "Geometric verification").
# Usage: scripts/verify-eval.sh [OUT_DIR]   (default data/eval-verify)
set -euo pipefail
cd "$(dirname "$0")/.."
B=./target/release/bowloc
D=../shared/datasets
OUT=${1:-data/eval-verify}
mkdir -p "$OUT"
run() { # name, then eval arguments
    local name=$1
    shift
    echo "## $name: bowloc eval $*"
    "$B" eval --no-plots --verify --out "$OUT/$name" "$@" 2>/dev/null | grep -v '^recommended' | grep -v 'results.md$'
}
for S in 1 2 3; do
    run "gp-k5000-seed$S" --dataset $D/gardens-point --words 5000 --vocab-seeds "$S,$S" \
        --rules none --set fixed=0.3 --runs 3 --cache data/eval-cache/gardens-point
    run "rtab-k1000-seed$S" --dataset $D/rtabmap-loop --words 1000 --vocab-seeds "$S,$S" \
        --rules none --set fixed=0.1 --set fixed=0.3 --runs 3 --cache data/eval-cache/rtabmap-loop
done
[ -n "${SEEDS_ONLY:-}" ] && exit 0
# model, estimator and top k, on vocabulary seed 1
for args in "--estimator ransac" "--model fundamental" "--model fundamental --estimator ransac --inlier-px 3" \
    "--inlier-px 4" "--inlier-px 12" "--verify-top-k 5" "--verify-top-k 20" "--max-word-pairs 1"; do
    name=$(echo "$args" | tr -d '-' | tr ' ' '_')
    # shellcheck disable=SC2086
    run "gp-$name" --dataset $D/gardens-point --words 5000 --vocab-seeds 1 --rules none --runs 1 \
        --cache data/eval-cache/gardens-point $args
    # shellcheck disable=SC2086
    run "rtab-$name" --dataset $D/rtabmap-loop --words 1000 --vocab-seeds 1 --rules none --set fixed=0.1 \
        --runs 3 --cache data/eval-cache/rtabmap-loop $args
done
