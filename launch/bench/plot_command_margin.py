#!/usr/bin/python3
"""Histogram of the driver's per-second command_age_max per variant (the CSV's first column:
command_margin.csv's physics priority, train_command_margin.csv's variant), with the
watchdog's 50 ms. Usage: plot_command_margin.py CSV PNG [TITLE]"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

LABELS = {"9": "physics below the controllers (9, shipped)", "20": "physics on top (20, before)"}


TITLE = "Command watchdog margin, pneumatic catch in real time (driver + 5 pools + MPC)"


def main(csv_path, png_path, title=TITLE):
    ages = {}  # variant -> ages, in the file's order
    with open(csv_path) as f:
        reader = csv.DictReader(f)
        key_column = reader.fieldnames[0]
        for row in reader:
            ages.setdefault(row[key_column], []).append(float(row["command_age_max_ms"]))
    fig, ax = plt.subplots(figsize=(7, 3.6))
    top = max([max(v) for v in ages.values() if v] + [60.0])
    bins = [x * 2.5 for x in range(int(top / 2.5) + 2)]
    for key, values in ages.items():
        ax.hist(values, bins=bins, alpha=0.6, label="%s, %d s" % (LABELS.get(key, key), len(values)))
    ax.axvline(50.0, color="r", linestyle="--", label="watchdog timeout")
    ax.set_xlabel("largest command age in a second (ms)")
    ax.set_ylabel("seconds")
    ax.set_yscale("log")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)


if __name__ == "__main__":
    main(*sys.argv[1:4])
