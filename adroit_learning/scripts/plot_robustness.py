#!/usr/bin/env python3
"""Plots of robustness_bench (thesis figs. 8.5 and 8.6) from the CSVs it writes in DIR:
smoothing.png (sample cost per iteration for each exploration-noise kernel width, one thin
line per seed, the seed mean bold) and robustness.png (object angle about the rotation axis
over time, one column per initial-state noise level, one row per controller: trained with
and without delayed initial-state noise; black = unperturbed, red = dropped).
Usage: plot_robustness.py DIR"""
import csv
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def smoothing(out):
    curves = defaultdict(dict)  # width -> seed -> [(iteration, cost)]
    for r in csv.DictReader(open(out + "/smoothing.csv")):
        curves[float(r["width"])].setdefault(r["seed"], []).append((int(r["iteration"]), float(r["cost_mean"])))
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, (width, seeds) in enumerate(sorted(curves.items())):
        colour = "C%d" % i
        for pts in seeds.values():
            ax.plot([p[0] for p in pts], [p[1] for p in pts], color=colour, alpha=0.3, lw=0.8)
        n = min(len(p) for p in seeds.values())
        mean = [sum(p[k][1] for p in seeds.values()) / len(seeds) for k in range(n)]
        ax.plot(range(n), mean, color=colour, lw=2.2, marker="o", ms=3,
                label="width %g steps%s" % (width, " (white)" if width == 0 else ""))
    ax.set_yscale("log")
    ax.set_xlabel("iteration")
    ax.set_ylabel("sample cost (mean of 5 rollouts)")
    ax.set_title("exploration-noise smoothing (fig. 8.5): thin = seeds, bold = mean")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out + "/smoothing.png", dpi=110)


def robustness(out):
    rows = list(csv.DictReader(open(out + "/robustness.csv")))
    table_rows = list(csv.DictReader(open(out + "/robustness_table.csv")))
    # One controller pair, as in the thesis figure: the seed whose pair differs most in drops.
    gap = defaultdict(int)
    for r in table_rows:
        gap[r["seed"]] += int(r["drops"]) * (1 if r["controller"] == "plain" else -1)
    seed = max(sorted(gap), key=lambda s: gap[s])
    levels = sorted({float(r["level"]) for r in rows if float(r["level"]) > 0})
    trace = defaultdict(list)  # (controller, level, trial) -> angles
    dropped = {}
    for r in rows:
        if r["seed"] != seed:
            continue
        key = (r["controller"], float(r["level"]), int(r["trial"]))
        trace[key].append(float(r["angle"]))
        dropped[key] = r["dropped"] == "1"
    table = defaultdict(lambda: [0, 0])  # (controller, level) -> [drops, trials] over all seeds
    for r in table_rows:
        t = table[(r["controller"], float(r["level"]))]
        t[0] += int(r["drops"])
        t[1] += int(r["trials"])
    controllers = [("robust", "trained with delayed initial-state noise"), ("plain", "trained without")]
    fig, axes = plt.subplots(2, len(levels), figsize=(4 * len(levels), 6.5), sharex=True, sharey=True)
    for row, (name, title) in enumerate(controllers):
        for col, level in enumerate(levels):
            ax = axes[row][col]
            for (c, l, i), angles in trace.items():
                if c == name and l == level:
                    ax.plot(angles, color="red" if dropped[(c, l, i)] else "C0", alpha=0.5, lw=0.9)
            nominal = trace.get((name, 0.0, 0))
            if nominal:
                ax.plot(nominal, color="black", lw=2)
            drops, trials = table[(name, level)]
            ax.set_title("%s, %.0f %% noise\n%d/%d dropped (all seeds)" % (name, level * 100, drops, trials), fontsize=9)
            if col == 0:
                ax.set_ylabel("angle about the axis [rad]\n" + title, fontsize=8)
            if row == 1:
                ax.set_xlabel("control step")
    fig.suptitle("robustness to initial-state noise (fig. 8.6), seed %s: black = unperturbed, red = dropped" % seed)
    fig.tight_layout()
    fig.savefig(out + "/robustness.png", dpi=110)


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    smoothing(sys.argv[1])
    robustness(sys.argv[1])


if __name__ == "__main__":
    main()
