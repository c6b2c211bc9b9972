#!/usr/bin/env python3
"""Queries whose top answer is right more often under one evaluation than
under another: the same setting read from two `results.json` that `bowloc
eval` wrote on the same dataset and vocabulary seeds (say the full search
on queries extracted whole and in tiles). Each query on each vocabulary
seed counts once, by the share of its runs answered right (runs of a full
search repeat one answer, so they are not counted apart), with a two-sided
sign test on the two counts.

    scripts/answer-flips.py A/results.json B/results.json "none +verify"
"""
import json
import sys
from math import comb


def tops(path, label):
    report = json.load(open(path))
    labels = [s["label"] for s in report["settings"]]
    if label not in labels:
        sys.exit(f"{path}: no setting `{label}` (it has {', '.join(labels)})")
    i = labels.index(label)
    per_seed = [
        [[(o["candidates"][0][0] if o["candidates"] else None) for o in run] for run in seed[i]]
        for seed in report["per_query"]["outcomes"]
    ]
    return report["per_query"]["truth"], per_seed


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    a_path, b_path, label = sys.argv[1:]
    truth, a = tops(a_path, label)
    truth_b, b = tops(b_path, label)
    if truth != truth_b or len(a) != len(b):
        sys.exit("the two evaluations are not of the same queries and vocabulary seeds")
    only_a = only_b = pairs = 0
    for seed_a, seed_b in zip(a, b):
        for q in range(len(truth)):
            share = lambda runs: sum(r[q] in truth[q] for r in runs) / len(runs)
            d = share(seed_a) - share(seed_b)
            pairs += 1
            only_a += d > 0
            only_b += d < 0
    n, k = only_a + only_b, min(only_a, only_b)
    p = min(1.0, 2 * sum(comb(n, i) for i in range(k + 1)) / 2**n) if n else 1.0
    print(
        f"`{label}`, {pairs} queries × seeds: right more often in A {only_a}, in B "
        f"{only_b} (sign test, two-sided p = {p:.3f})"
    )


main()
