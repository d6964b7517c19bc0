#!/usr/bin/env python3
"""Learning curve of a network distillation (train_network_policy, thesis 11.6): training and
held-out loss per epoch (normalised mean squared error), one colour per round (round 0: the
local policies' rollouts; round k: after the k-th DAgger aggregation), epochs of later rounds
after the earlier ones, and each round's mean predictor on its held-out set (dotted).
Usage: plot_network_loss.py loss.csv out.png [title]"""
import csv
import math
import sys
from collections import OrderedDict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    rounds = OrderedDict()  # round -> rows
    for r in csv.DictReader(open(sys.argv[1])):
        rounds.setdefault(int(r["round"]), []).append(r)
    if not rounds:
        sys.exit("no epochs in " + sys.argv[1])
    fig, ax = plt.subplots(figsize=(7, 4.5))
    offset = 0
    for i, (k, rows) in enumerate(rounds.items()):
        colour = "C%d" % (i % 10)
        x = [offset + int(r["epoch"]) for r in rows]
        name = "local policies" if k == 0 else "DAgger %d" % k
        samples = rows[0]["samples"]
        ax.plot(x, [float(r["train_loss"]) for r in rows], color=colour, ls="--", lw=1,
                label="%s: train (%s samples)" % (name, samples))
        held = [float(r["held_out_loss"]) for r in rows]
        if not all(math.isnan(h) for h in held):
            ax.plot(x, held, color=colour, lw=1.8, label="%s: held out" % name)
        mean = float(rows[0]["mean_predictor_loss"])
        if not math.isnan(mean):
            ax.plot([x[0], x[-1]], [mean, mean], color=colour, ls=":", lw=1.2, label="%s: mean predictor" % name)
        offset = x[-1]
    ax.set_yscale("log")
    ax.set_xlabel("epoch (rounds one after another)")
    ax.set_ylabel("loss [normalised MSE]")
    ax.set_title(sys.argv[3] if len(sys.argv) > 3 else "network distillation")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=90)


if __name__ == "__main__":
    main()
