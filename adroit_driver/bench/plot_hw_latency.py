#!/usr/bin/python3
"""Plots hw_latency_bench's per-sample CSV: histograms of the sensor-sample -> valve-frame latency,
relay baseline vs pools ('first' frame and 'all' valve groups, counting the frames with new values;
'all' counting any frame, as first defined), and 'all' over the run.

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
PANELS = (("first_new_ms", "first valve frame with new values"), ("all_new_ms", "all groups, new values"),
          ("all_ms", "all groups, any frame"))


def percentile(values, q):
    s = sorted(values)
    return s[min(len(s) - 1, max(0, int(math.ceil(q / 100.0 * len(s))) - 1))] if s else float("nan")


def main(csv_path, png_path):
    rows = list(csv.DictReader(open(csv_path)))
    data = {}  # mode -> column -> values (samples without an answer left out)
    for r in rows:
        d = data.setdefault(r["mode"], {})
        for key in ("first_new_ms", "all_new_ms", "all_ms", "all_tag_ms"):
            v = float(r[key])
            if not math.isnan(v):
                d.setdefault(key, []).append(v)
    fig = plt.figure(figsize=(15, 8))
    grid = fig.add_gridspec(2, 3, height_ratios=[1, 0.8])
    top = max([percentile(v, 99.9) for d in data.values() for v in d.values() if v] + [TARGET_MS * 1.5])
    step = top / 80.0
    bins = [i * step for i in range(82)]
    for col, (key, title) in enumerate(PANELS):
        ax = fig.add_subplot(grid[0, col])
        for mode in ("relay", "pools"):
            values = data.get(mode, {}).get(key, [])
            if values:
                ax.hist([min(v, bins[-1]) for v in values], bins=bins, alpha=0.55, color=COLORS[mode],
                        label="%s\np50 %.2f, p99 %.2f ms" % (LABELS[mode], percentile(values, 50),
                                                             percentile(values, 99)))
        tagged = data.get("relay", {}).get("all_tag_ms", [])
        if key == "all_new_ms" and tagged:  # the exact match of the relay's frames: the check of 'new values'
            ax.hist([min(v, bins[-1]) for v in tagged], bins=bins, histtype="step", color="k", linewidth=0.8,
                    label="relay, frames matched to their sample\np50 %.2f, p99 %.2f ms" % (
                        percentile(tagged, 50), percentile(tagged, 99)))
        ax.axvline(TARGET_MS, color="k", linestyle="--", linewidth=1, label="required p99 %g ms" % TARGET_MS)
        ax.set_yscale("log")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("sensor sample in -> valve frames out [ms] (last bin: beyond)", fontsize=8)
        ax.set_ylabel("samples")
        ax.legend(fontsize=7)
    ax = fig.add_subplot(grid[1, :])
    for mode in ("relay", "pools"):
        points = [(float(r["t_s"]), float(r["all_new_ms"])) for r in rows
                  if r["mode"] == mode and not math.isnan(float(r["all_new_ms"]))]
        if points:
            ax.plot([p[0] for p in points], [p[1] for p in points], ".", markersize=1.5, color=COLORS[mode],
                    label=LABELS[mode])
    ax.axhline(TARGET_MS, color="k", linestyle="--", linewidth=1)
    ax.set_ylim(0, top)
    ax.set_xlabel("run time [s] (blocks alternate)")
    ax.set_ylabel("all groups, new values [ms]")
    ax.legend(fontsize=7, markerscale=6, loc="upper right")
    fig.suptitle("Hardware driver: sensor frame in -> valve frames out, emulated CAN buses (%d samples)" % len(rows))
    fig.tight_layout()
    fig.savefig(png_path, dpi=100)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
