#!/usr/bin/env python3
"""Where a rule's searches stop, from a `bowloc eval` results.json.

For each setting: the share of searches (seeds x runs x queries) its rule
stopped before the last feature, the median and mean share of the features
those searches used, and the mean over all searches. A search the rule does
not stop reads every feature, so a rule whose stops come late or seldom
cannot use few features on average, however it is tuned. Against a baseline
setting (default "none +verify", the verified full search): how many stopped
searches answer wrong at top-1 where the baseline answers right (what the
stops cost), how many answer right where it does not, and their difference
in points of recall@1. Last, the share of searches that would have to stop,
at the features the stopped ones used on average, for a mean of half the
features.

    scripts/early-stops.py data/eval/<run>/results.json [BASELINE]
"""
import json
import statistics
import sys


def main():
    path = sys.argv[1]
    report = json.load(open(path))
    labels = [s["label"] for s in report["settings"]]
    baseline = sys.argv[2] if len(sys.argv) > 2 else "none +verify"
    if baseline not in labels:
        sys.exit(f"{path}: no setting {baseline!r} (settings: {', '.join(labels)})")
    base = labels.index(baseline)
    truth = [set(t) for t in report["per_query"]["truth"]]
    outcomes = report["per_query"]["outcomes"]  # [seed][setting][run][query]

    def right(o, q):
        return bool(o["candidates"]) and o["candidates"][0][0] in truth[q]

    print(f"{path}: searches over seeds x runs x queries; stopped = ended by the rule before the last feature")
    print(f"{'setting':42} {'stopped':>8} {'their features, median / mean':>30} {'all, mean':>10} "
          f"{'worse than ' + baseline:>24} {'better':>7} {'net, points':>11} {'stops for a 50 % mean':>22}")
    for i, label in enumerate(labels):
        stopped, fractions, worse, better, searches = 0, [], 0, 0, 0
        all_fractions = []
        for seed in outcomes:
            for run, base_run in zip(seed[i], seed[base]):
                for q, (o, b) in enumerate(zip(run, base_run)):
                    searches += 1
                    f = o["used"] / o["total"] if o["total"] else 1.0
                    all_fractions.append(f)
                    if o["stop"] == "rule" and o["used"] < o["total"]:
                        stopped += 1
                        fractions.append(f)
                        worse += right(b, q) and not right(o, q)
                        better += right(o, q) and not right(b, q)
        theirs = (f"{100 * statistics.median(fractions):.1f} / {100 * statistics.mean(fractions):.1f} %"
                  if fractions else "-")
        # mean = s * m + (1 - s) = 0.5 with m the stopped searches' mean
        needed = (f"{100 * 0.5 / (1 - statistics.mean(fractions)):.1f}%"
                  if fractions and statistics.mean(fractions) < 0.5 else "-")
        print(f"{label:42} {100 * stopped / searches:7.1f}% {theirs:>30} "
              f"{100 * statistics.mean(all_fractions):9.1f}% {worse:>24} {better:>7} "
              f"{100 * (worse - better) / searches:11.1f} {needed:>22}")


if __name__ == "__main__":
    main()
