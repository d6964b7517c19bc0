#!/usr/bin/python3
"""Latency histogram of teleop_bench.py's latency.csv: the teleop pipeline (glove record ->
physics step) next to the baseline (direct command -> physics step)."""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(csv_path, png_path):
    data = {}
    with open(csv_path) as f:
        for row in csv.DictReader(f):
            data.setdefault(row["source"], []).append(1e3 * float(row["latency_s"]))
    fig, ax = plt.subplots(figsize=(8, 4.5))
    top = max(max(v) for v in data.values() if v)
    bins = [i * 0.1 for i in range(int(min(top, 15) / 0.1) + 2)]
    labels = {"pipeline": "glove record -> physics step (teleop)", "baseline": "rospy command -> physics step (baseline)",
              "serial": "emulator write -> glove arrival"}
    for name in ("baseline", "pipeline", "serial"):
        values = sorted(data.get(name, []))
        if not values:
            continue
        p50, p99 = values[len(values) // 2], values[min(len(values) - 1, int(0.99 * len(values)))]
        ax.hist(values, bins=bins, alpha=0.55, label="%s (p50 %.2f, p99 %.2f ms)" % (labels[name], p50, p99))
    ax.axvline(5, color="k", linestyle="--", linewidth=1, label="required p50 5 ms")
    ax.axvline(10, color="k", linestyle=":", linewidth=1, label="required p99 10 ms")
    ax.set_xlabel("latency [ms]")
    ax.set_ylabel("commands")
    ax.set_title("Glove teleop latency, end to end with the emulator (2 cores)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
