#!/usr/bin/python3
"""Histogram of the driver's per-second command_age_max (command_margin.csv) per physics
priority, with the watchdog's 50 ms. Usage: plot_command_margin.py CSV PNG"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

LABELS = {"9": "physics below the controllers (9, shipped)", "20": "physics on top (20, before)"}


def main(csv_path, png_path):
    ages = {}
    with open(csv_path) as f:
        for row in csv.DictReader(f):
            ages.setdefault(row["physics_priority"], []).append(float(row["command_age_max_ms"]))
    fig, ax = plt.subplots(figsize=(7, 3.6))
    top = max([max(v) for v in ages.values() if v] + [60.0])
    bins = [x * 2.5 for x in range(int(top / 2.5) + 2)]
    for key in ("9", "20"):
        if key in ages:
            ax.hist(ages[key], bins=bins, alpha=0.6, label="%s, %d s" % (LABELS.get(key, key), len(ages[key])))
    ax.axvline(50.0, color="r", linestyle="--", label="watchdog timeout")
    ax.set_xlabel("largest command age in a second (ms)")
    ax.set_ylabel("seconds")
    ax.set_yscale("log")
    ax.set_title("Command watchdog margin, pneumatic catch in real time (driver + 5 pools + MPC)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
