#!/usr/bin/env bash
# How the service's default stopping rule threshold is chosen: on one shared
# dataset, the smallest threshold of a grid that loses at most 1 point of
# recall@1 and of recall@5 against the full search on every vocabulary seed
# (3 seeds × 3 feature orders, queries streamed in 2x2+24 tiles, the default
# tile order); then the same threshold on the dataset kept aside. Prints, for
# every threshold, the worst seed's loss on each dataset, the share of
# features and the request time against the whole-image full search (mean
# and median over seeds × queries × runs), then each seed's recall@1 and
# recall top-1 @90 % precision (by distinctness) on the dataset chosen on.
# Several datasets may be kept aside; each is checked alone.
#
# By default the rule is tried as the service runs it: with geometric
# verification (the configured model) and the verified stop beside it
# (`RULE=T+verified=M`), against the verified full search.
#
#   scripts/choose-default.sh [OUT]     (default OUT: data/eval/choose)
#
# Environment: RULE (default place-z), WARMUP (default 20), GRID (default
# "1 1.25 1.5 1.75 2 2.25 2.5 3"), CHOOSE and ASIDE (NAME:WORDS, NAME a
# shared dataset or a dataset folder, e.g.
# data/datasets/gardens-point-reversed from scripts/reversed-datasets.sh;
# default gardens-point:5000 and rtabmap-loop:1000; ASIDE may list
# several, space-separated), VERIFIED (the verified stop's inliers,
# default 12; 0: the vote rule alone, without verification) and
# MODEL (the verification model, default the configuration's); EVAL_ARGS,
# more `bowloc eval` options for both datasets (e.g. "--min-inliers 6").
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-data/eval/choose}
rule=${RULE:-place-z}
warmup=${WARMUP:-20}
grid=${GRID:-1 1.25 1.5 1.75 2 2.25 2.5 3}
verified=${VERIFIED:-12}
choose=${CHOOSE:-gardens-point:5000}
aside=${ASIDE:-rtabmap-loop:1000}
[ -x target/release/bowloc ] || cargo build --release
sets=()
verify=()
if [ "$verified" = 0 ]; then
  for t in $grid; do sets+=(--set "$rule=$t@$warmup"); done
else
  for t in $grid; do sets+=(--set "$rule=$t+verified=$verified@$warmup"); done
  verify=(--verify ${MODEL:+--model "$MODEL"})
fi
# a dataset's folder: NAME in the shared datasets, or NAME itself when it
# names a folder
root() { case $1 in */*) echo "$1" ;; *) echo "../shared/datasets/$1" ;; esac; }
results=()
for dataset in "$choose" $aside; do
  name=${dataset%%:*}
  ./target/release/bowloc --log warn eval --dataset "$(root "$name")" --words "${dataset##*:}" \
    --runs 3 --vocab-seeds 3 --rules none "${verify[@]}" "${sets[@]}" ${EVAL_ARGS:-} --no-plots --out "$out/$(basename "$name")" >/dev/null
  results+=("$out/$(basename "$name")/results.json")
done
# the full search compared with: verified if the rule is
full_label=none
[ "$verified" = 0 ] || full_label="none +verify"
python3 - "$full_label" "${results[@]}" <<'PY'
import json, sys

def rows(path):
    return rows_against(path, sys.argv[1])

def rows_against(path, full_label):
    d = json.load(open(path))
    full = next(s for s in d["settings"] if s["label"] == full_label)
    out = []
    for s in d["settings"]:
        if s["label"].startswith("none"):
            continue
        loss = max(
            100 * (f - r)
            for key in ("recall_at_1", "recall_at_5")
            for f, r in zip(full[key]["per_seed"], s[key]["per_seed"])
        )
        out.append((s["label"], loss, 100 * s["fraction"]["mean"],
                    s["time_share_whole"]["mean"], s["time_share_whole"]["median"]))
    return d["dataset"]["name"], out

(chosen_on, a), *aside = (rows(path) for path in sys.argv[2:])
pick = next((r for r in a if r[1] <= 1.0 + 1e-9), None)
for i, (label, loss, feat, mean, median) in enumerate(a):
    mark = "  <- chosen" if pick and label == pick[0] else ""
    others = "".join(
        f" | {name}: worst-seed loss {o[1]:4.1f}, features {o[2]:5.1f} %, x full {o[3]:.3f} / {o[4]:.3f}"
        for name, other in aside
        for o in [other[i]]
    )
    print(f"{label:22} {chosen_on}: worst-seed loss {loss:4.1f} points, features {feat:5.1f} %, "
          f"x full {mean:.3f} / {median:.3f}{others}{mark}")
if pick is None:
    print(f"no threshold of the grid loses at most 1 point on {chosen_on}")
if sys.argv[1] != "none":
    # the loss against the full search without verification, which the
    # verified one itself may lose to on a map unlike the one chosen on
    plain = [rows_against(path, "none") for path in sys.argv[2:]]
    for i, (label, *_rest) in enumerate(a):
        print(f"{label:22} against the unverified full search, worst-seed loss: "
              + ", ".join(f"{name} {r[i][1]:.1f}" for name, r in plain))

# per vocabulary seed on the dataset chosen on: recall@1 and the top
# candidate's recall at 90 % precision by distinctness (how well the
# answers can be trusted by a cut), the full search first
d = json.load(open(sys.argv[2]))
print(f"{chosen_on} per vocabulary seed: recall@1 | recall top-1 @90 % precision by distinctness")
for s in d["settings"]:
    if s["label"] == "none" and sys.argv[1] != "none":
        continue
    per = lambda key: " / ".join(f"{100 * v:.1f}" for v in s[key]["per_seed"])
    print(f"  {s['label']:40} {per('recall_at_1')} | {per('recall90_top1_distinct')}")
PY
