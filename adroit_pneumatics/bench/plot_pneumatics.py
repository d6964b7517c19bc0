#!/usr/bin/python3
"""Plots of pneumatics_bench from the CSV files it wrote into DIR.

    plot_pneumatics.py DIR

  tracking_<case>.csv  -> tracking_<case>.png: reference, iLQG, PIDF (and the floor where the
                          file has one) over time, valve commands below (thesis figs. 5.15-5.17)
  identification_<case>.csv -> identification_<case>.png: measured pressure and the open-loop
                          predictions of the saturating form and eq. 5.5, restarted from the
                          measurement at every window start, valve command below
"""
import csv
import glob
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read_columns(path):
    with open(path) as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return {}
    return {key: [float(r[key]) for r in rows] for key in rows[0]}


def pressure_figure(c):
    """Pressure panel over a command panel; returns fig, top, bottom and a column in kPa."""
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 6), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    return fig, top, bottom, lambda key: [v / 1e3 for v in c[key]]


def finish(fig, top, bottom, path):
    top.set_ylabel("pressure [kPa]")
    top.legend(loc="upper right", fontsize=8)
    bottom.set_ylabel("valve command [V]")
    bottom.set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path[:-len(".csv")] + ".png", dpi=90)
    plt.close(fig)


def plot_tracking(path):
    """Columns: t, reference, ilqg, pidf [, floor], ilqg_u, pidf_u (s, Pa, V)."""
    c = read_columns(path)
    if not c:
        return
    case = os.path.basename(path)[len("tracking_"):-len(".csv")]
    fig, top, bottom, kpa = pressure_figure(c)
    top.plot(c["t"], kpa("reference"), color="black", linewidth=1.0, label="reference")
    if "floor" in c:
        top.plot(c["t"], kpa("floor"), color="tab:green", linewidth=0.8, linestyle="--",
                 label="floor (valve at the limit at each jump, oracle stop)")
    top.plot(c["t"], kpa("pidf"), color="tab:orange", linewidth=0.9, label="PIDF")
    top.plot(c["t"], kpa("ilqg"), color="tab:blue", linewidth=0.9, label="iLQG")
    top.set_title("pressure tracking: " + case.replace("_", " "))
    bottom.plot(c["t"], c["pidf_u"], color="tab:orange", linewidth=0.8, label="PIDF")
    bottom.plot(c["t"], c["ilqg_u"], color="tab:blue", linewidth=0.8, label="iLQG")
    bottom.legend(loc="upper right", fontsize=8)
    finish(fig, top, bottom, path)


def plot_identification(path, window=2.0):
    """Columns: t, volts, measured, saturating, eq55 (s, V, Pa); windows of `window` s."""
    c = read_columns(path)
    if not c:
        return
    case = os.path.basename(path)[len("identification_"):-len(".csv")]
    fig, top, bottom, kpa = pressure_figure(c)
    top.plot(c["t"], kpa("measured"), color="black", linewidth=1.0, label="measured")
    top.plot(c["t"], kpa("eq55"), color="tab:orange", linewidth=0.9, label="eq. 5.5")
    top.plot(c["t"], kpa("saturating"), color="tab:blue", linewidth=0.9, label="saturating form")
    starts = [k * window for k in range(int(c["t"][-1] / window) + 1)]
    for ax in (top, bottom):
        for t in starts:
            ax.axvline(t, color="grey", linewidth=0.6, linestyle=":")
    top.set_title("open-loop prediction, restarted from the measurement every %g s: %s" % (window, case))
    bottom.plot(c["t"], c["volts"], color="tab:gray", linewidth=0.8)
    finish(fig, top, bottom, path)


def main(out_dir):
    for path in sorted(glob.glob(os.path.join(out_dir, "tracking_*.csv"))):
        plot_tracking(path)
    for path in sorted(glob.glob(os.path.join(out_dir, "identification_*.csv"))):
        plot_identification(path)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
