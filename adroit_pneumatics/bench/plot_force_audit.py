#!/usr/bin/python3
"""Force tracking of a run as force_tracking_audit --csv wrote it.

    plot_force_audit.py forces.csv out.png

Three finger cylinders whose desired tension moved the most, each over the 0.4 s around its
largest jump: desired, measured and the per-sample floor's tension (a cylinder that learns of
each desired value when it comes, with an exact model)."""
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.realpath(__file__)))
from plot_pneumatics import read_columns  # noqa: E402


def main(csv_path, png_path, cylinders=3, window=0.4):
    c = read_columns(csv_path)
    if not c:
        sys.exit(f"plot_force_audit: {csv_path} has no rows")
    t = c["time"]
    names = [k[:-len(":desired")] for k in c if k.endswith(":desired") and not k.startswith(("A_WR", "A_AR"))]
    if not names:
        sys.exit(f"plot_force_audit: {csv_path} has no finger cylinder")

    def travel(name):
        d = c[name + ":desired"]
        return sum(abs(b - a) for a, b in zip(d, d[1:]))

    chosen = sorted(names, key=travel, reverse=True)[:cylinders]
    fig, axes = plt.subplots(len(chosen), 1, figsize=(10, 3 * len(chosen)))
    for ax, name in zip(axes if len(chosen) > 1 else [axes], chosen):
        d = c[name + ":desired"]
        jump = max(range(1, len(d)), key=lambda k: abs(d[k] - d[k - 1]))
        lo, hi = t[jump] - window / 2, t[jump] + window / 2
        idx = [k for k in range(len(t)) if lo <= t[k] <= hi]
        ts = [t[k] for k in idx]
        ax.step(ts, [d[k] for k in idx], where="post", color="k", label="desired (plan)")
        ax.plot(ts, [c[name + ":measured"][k] for k in idx], ".-", color="tab:red", label="measured")
        ax.plot(ts, [c[name + ":floor_per_sample"][k] for k in idx], ".-", color="tab:green", alpha=0.7,
                label="floor, per sample")
        ax.set_title(name, fontsize=10)
        ax.set_ylabel("tension [N]")
        ax.grid(alpha=0.3)
    axes_list = axes if len(chosen) > 1 else [axes]
    axes_list[0].legend(loc="upper right", fontsize=8)
    axes_list[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(png_path, dpi=90)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: plot_force_audit.py forces.csv out.png")
    main(sys.argv[1], sys.argv[2])
