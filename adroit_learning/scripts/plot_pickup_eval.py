#!/usr/bin/env python3
"""Plots of a pickup_eval run (thesis ch. 11). Usage: plot_pickup_eval.py DIR

Reads DIR/sweep.csv and DIR/summary.csv and writes
  DIR/sweep.png   one row per policy over the initial rod angle 0..180 degrees (figs. 11.2-11.10):
                  green circles succeeded, red crosses failed, y = the rollout's cost; the title
                  gives the success percentage, the y label the mean cost, and the angles the
                  policy was trained for (a library: every entry's) are solid black lines;
  DIR/random.png  success at the random initial yaws per policy with the 95 % Wilson interval.
"""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def number(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def sweep_by_policy(rows):
    policies = {}
    for r in rows:
        policies.setdefault(r["policy"], []).append(r)
    return policies


def plot_sweep(ax, name, rows, trained):
    yaw = [number(r["yaw_deg"]) for r in rows]
    cost = [number(r["cost"]) for r in rows]
    ok = [r["success"] == "1" for r in rows]
    finite = [c for c in cost if math.isfinite(c)]
    top = max(finite) if finite else 1.0
    # A rollout that failed before T has no cost: drawn at the top of the axis.
    y = [c if math.isfinite(c) else top for c in cost]
    ax.plot([a for a, s in zip(yaw, ok) if s], [v for v, s in zip(y, ok) if s], "o", color="tab:green",
            markerfacecolor="none", label="success")
    ax.plot([a for a, s in zip(yaw, ok) if not s], [v for v, s in zip(y, ok) if not s], "x", color="tab:red",
            label="failure")
    for t in trained:
        ax.axvline(t, color="black", linewidth=1.5)
    n = len(rows)
    rate = 100.0 * sum(ok) / n if n else 0.0
    ax.set_title(f"{name}: {rate:.1f} % success ({sum(ok)}/{n})", fontsize=9)
    mean = sum(finite) / len(finite) if finite else math.nan
    ax.set_ylabel(f"cost (mean {mean:.3g})", fontsize=8)
    ax.set_xlim(-4, 184)  # a trained angle of 0 stays visible
    ax.set_xticks(range(0, 181, 30))
    ax.margins(y=0.15)
    ax.grid(True, alpha=0.3)


def trained_yaws(summary):
    out = {}
    for r in summary:
        out[r["policy"]] = [float(w) for w in (r.get("trained_yaws") or "").split()]
    return out


def sweep_figure(directory, summary):
    policies = sweep_by_policy(read_rows(os.path.join(directory, "sweep.csv")))
    if not policies:
        raise SystemExit("no sweep rows in " + directory)
    trained = trained_yaws(summary)
    fig, axes = plt.subplots(len(policies), 1, figsize=(7, 1.9 * len(policies) + 0.6), sharex=True, squeeze=False)
    for ax, (name, rows) in zip(axes[:, 0], policies.items()):
        plot_sweep(ax, name, rows, trained.get(name, []))
    axes[-1, 0].set_xlabel("initial rod angle [deg] (tube axis from +x towards +y)")
    axes[0, 0].legend(loc="upper right", fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(directory, "sweep.png"), dpi=90)
    plt.close(fig)


def random_figure(directory, summary):
    names = [r["policy"] for r in summary]
    rate = [number(r["random_success_percent"]) for r in summary]
    low = [number(r["random_ci_low_percent"]) for r in summary]
    high = [number(r["random_ci_high_percent"]) for r in summary]
    err = [[max(0.0, p - lo) for p, lo in zip(rate, low)], [max(0.0, hi - p) for p, hi in zip(rate, high)]]
    trials = summary[0]["random_trials"] if summary else "0"
    fig, ax = plt.subplots(figsize=(max(4.0, 0.9 * len(names) + 2), 3.6))
    ax.bar(range(len(names)), rate, yerr=err, capsize=4, color="tab:blue")
    ax.set_xticks(range(len(names)))
    ax.set_xticklabels(names, rotation=30, ha="right", fontsize=8)
    ax.set_ylim(0, 105)
    ax.set_ylabel("success [%] (95 % Wilson interval)")
    ax.set_title(f"pickup success at {trials} random initial yaws")
    ax.grid(True, axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(directory, "random.png"), dpi=90)
    plt.close(fig)


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    directory = sys.argv[1]
    summary = read_rows(os.path.join(directory, "summary.csv"))
    sweep_figure(directory, summary)
    random_figure(directory, summary)


if __name__ == "__main__":
    main()
