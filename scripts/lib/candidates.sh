# Shared by verify-orders.sh and verify-descriptors.sh. Source it from the
# repository's root:  . scripts/lib/candidates.sh
#
#   candidate_csvs OUT NAME:WORDS[:GRID] [descriptors]
#       writes examples/candidates.rs's CSV for vocabulary seeds 1 to 3 to
#       OUT/NAME-WORDS-GRID-SEED.csv (GRID as for `bowloc eval --tiles`,
#       default 1x1: whole queries) and sets STEM to NAME-WORDS-GRID.
#       The example is built on first use.

candidate_csvs() {
  local out=$1 set=$2 extra=${3:-} name words grid seed
  cargo build --release --quiet --example candidates
  IFS=: read -r name words grid <<<"$set"
  grid=${grid:-1x1}
  mkdir -p "$out"
  for seed in 1 2 3; do
    ./target/release/examples/candidates "../shared/datasets/$name" "$words" "$seed" "$grid" $extra \
      >"$out/$name-$words-$grid-$seed.csv" 2>/dev/null
  done
  STEM="$name-$words-$grid"
}
