#!/usr/bin/env python3
"""Learning curve of a trainer run (thesis fig. 8.4): cost mean +- std per iteration, and the
mean joint RMS error at T. Usage: plot_learning_curve.py learning_curve.csv out.png [label]"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    rows = [r for r in csv.DictReader(open(sys.argv[1])) if r["ok"] == "1"]
    if not rows:
        sys.exit("no completed iterations in " + sys.argv[1])
    it = [int(r["iteration"]) for r in rows]
    mean = [float(r["cost_mean"]) for r in rows]
    std = [float(r["cost_std"]) for r in rows]
    rms = [float(r["joint_rms_mean"]) for r in rows]
    fig, (a, b) = plt.subplots(2, 1, figsize=(6, 5), sharex=True)
    a.errorbar(it, mean, yerr=std, marker="o", capsize=3)
    a.set_yscale("log")
    a.set_ylabel("cost per rollout")
    a.set_title(sys.argv[3] if len(sys.argv) > 3 else "learning curve")
    b.plot(it, rms, marker="o")
    b.set_ylabel("joint RMS error at T [rad]")
    b.set_xlabel("iteration")
    b.grid(True, alpha=0.3)
    a.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(sys.argv[2], dpi=90)


if __name__ == "__main__":
    main()
