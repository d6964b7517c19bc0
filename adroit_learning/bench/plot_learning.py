#!/usr/bin/python3
"""Plot of learning_bench from the CSV file it wrote into DIR.

    plot_learning.py DIR

  phases.csv -> phases.png: per iteration, the trainer's compute as stacked bars (GMM fit,
                dynamics fit, cost expansion, KL update) next to a bar of the rollout time of
                the in-process simulation backend (5 rollouts of 100 control steps), and the
                1 s target.
"""
import csv
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = sys.argv[1]
    with open(os.path.join(out, "phases.csv")) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        sys.exit("phases.csv is empty")
    it = [int(r["iteration"]) for r in rows]
    width = 0.38
    fig, ax = plt.subplots(figsize=(9, 4.5))
    bottom = [0.0] * len(rows)
    for key, label in (("gmm_s", "GMM fit"), ("dynamics_s", "dynamics fit"), ("cost_s", "cost expansion"),
                       ("kl_s", "KL update")):
        values = [float(r[key]) for r in rows]
        ax.bar([i - width / 2 for i in it], values, width, bottom=bottom, label=label)
        bottom = [b + v for b, v in zip(bottom, values)]
    ax.bar([i + width / 2 for i in it], [float(r["rollout_s"]) for r in rows], width, color="0.6",
           label="5 rollouts, SimulatedRobot")
    ax.axhline(1.0, color="k", linestyle="--", linewidth=1, label="target 1 s")
    ax.set_xticks(it)
    ax.set_xlabel("iteration")
    ax.set_ylabel("time [s]")
    ax.set_title("learning_bench: compute per iteration (nx 100, nu 40, T 100, N 5)")
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    path = os.path.join(out, "phases.png")
    fig.savefig(path, dpi=110)
    print("wrote", path)


if __name__ == "__main__":
    main()
