#!/usr/bin/python3
"""Plots hw_latency_bench's per-sample CSV: histograms of the sensor-sample -> valve-frame latency
('first' frame and 'all' valve groups), relay baseline vs pools, and the latency over the run.

usage: plot_hw_latency.py hw_latency.csv hw_latency.png
"""
import csv
import math
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

TARGET_MS = 2.0
COLORS = {"relay": "tab:blue", "pools": "tab:orange"}
LABELS = {"relay": "relay (baseline: 0 V on each state)", "pools": "pools (iLQG, tick on state)"}


def percentile(values, q):
    s = sorted(values)
    return s[min(len(s) - 1, int(math.ceil(q / 100.0 * len(s))) - 1)] if s else float("nan")


def main(csv_path, png_path):
    rows = list(csv.DictReader(open(csv_path)))
    data = {}  # mode -> field -> values (samples without a frame left out of the histograms)
    series = {}  # mode -> [(t, all_ms)]
    for r in rows:
        d = data.setdefault(r["mode"], {"first_ms": [], "all_ms": []})
        for key in d:
            v = float(r[key])
            if not math.isnan(v):
                d[key].append(v)
        if not math.isnan(float(r["all_ms"])):
            series.setdefault(r["mode"], []).append((float(r["t_s"]), float(r["all_ms"])))
    fig = plt.figure(figsize=(11, 7.5))
    grid = fig.add_gridspec(2, 2, height_ratios=[1, 0.8])
    top = max([percentile(d[k], 99.9) for d in data.values() for k in d if d[k]] + [TARGET_MS * 1.5])
    step = top / 80.0
    bins = [i * step for i in range(82)]
    for col, (key, title) in enumerate((("first_ms", "first valve frame"), ("all_ms", "all valve groups updated"))):
        ax = fig.add_subplot(grid[0, col])
        for mode in ("relay", "pools"):
            values = data.get(mode, {}).get(key, [])
            if not values:
                continue
            clipped = [min(v, bins[-1]) for v in values]
            ax.hist(clipped, bins=bins, alpha=0.55, color=COLORS[mode],
                    label="%s\np50 %.2f, p99 %.2f ms" % (LABELS[mode], percentile(values, 50), percentile(values, 99)))
        ax.axvline(TARGET_MS, color="k", linestyle="--", linewidth=1, label="required p99 %g ms" % TARGET_MS)
        ax.set_yscale("log")
        ax.set_xlabel("sensor sample in -> %s [ms] (last bin: beyond)" % title)
        ax.set_ylabel("samples")
        ax.legend(fontsize=7)
    ax = fig.add_subplot(grid[1, :])
    for mode in ("relay", "pools"):
        points = series.get(mode, [])
        if points:
            ax.plot([p[0] for p in points], [p[1] for p in points], ".", markersize=1.5, color=COLORS[mode],
                    label=LABELS[mode])
    ax.axhline(TARGET_MS, color="k", linestyle="--", linewidth=1)
    ax.set_ylim(0, top)
    ax.set_xlabel("run time [s] (blocks alternate)")
    ax.set_ylabel("all groups [ms]")
    ax.legend(fontsize=7, markerscale=6, loc="upper right")
    fig.suptitle("Hardware driver: sensor frame in -> valve frames out (emulated CAN buses, %d samples)" % len(rows))
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
