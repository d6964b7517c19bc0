#!/usr/bin/python3
"""Plots of mpc_success: per task, success rate per variant and the first trial's error over time.

    plot_success.py DIR    (reads DIR/success_trials.csv, DIR/success_traces.csv; writes DIR/success_<task>.png)
"""
import csv
import os
import sys
from collections import defaultdict

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

UNITS = {"catch": ("object to goal [m]", 0.03), "relocate": ("object to goal [m]", 0.03),
         "type": ("keys still to type", None)}


def main(out_dir):
    trials = defaultdict(lambda: defaultdict(list))
    with open(os.path.join(out_dir, "success_trials.csv")) as f:
        for row in csv.DictReader(f):
            value = (float(row["keys_correct"]) / float(row["keys_total"]) if row["task"] == "type"
                     else float(row["success"]))
            trials[row["task"]][row["variant"]].append(value)
    traces = defaultdict(lambda: defaultdict(lambda: ([], [])))
    with open(os.path.join(out_dir, "success_traces.csv")) as f:
        for row in csv.DictReader(f):
            t, e = traces[row["task"]][row["variant"]]
            t.append(float(row["t"]))
            e.append(float(row["error"]))
    for task, by_variant in trials.items():
        fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.4))
        names = list(by_variant)
        rates = [100.0 * sum(v) / len(v) for v in by_variant.values()]
        left.bar(names, rates, color="tab:blue")
        left.tick_params(axis="x", labelrotation=30, labelsize=8)
        target = 90 if task == "type" else 80
        left.axhline(target, color="tab:red", linestyle="--", label="target %d %%" % target)
        left.set_ylim(0, 100)
        left.set_ylabel("keys correct [%]" if task == "type" else "successful trials [%]")
        left.set_title("%s: %d trials per variant" % (task, len(next(iter(by_variant.values())))))
        left.legend(loc="upper right")
        label, tolerance = UNITS[task]
        for variant, (t, e) in traces[task].items():
            right.plot(t, e, label=variant)
        if tolerance:
            right.axhline(tolerance, color="tab:red", linestyle="--", label="success tolerance")
        right.set_xlabel("simulated time [s]")
        right.set_ylabel(label)
        right.set_title("trial 0")
        right.legend(loc="upper right")
        fig.tight_layout()
        fig.savefig(os.path.join(out_dir, "success_%s.png" % task), dpi=90)
        plt.close(fig)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
