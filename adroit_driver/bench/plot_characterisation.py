#!/usr/bin/python3
"""Plots of adroit_characterise's report from the CSV files it wrote (one PNG per experiment that ran),
each figure with the thesis value marked. Prints the names of the PNG files written.

usage: plot_characterisation.py OUTPUT_DIR
"""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

THESIS = {"bang_bang_hz": 7.0, "movement_ms": 70.0, "pressure_ms": 8.0, "motion_ms": 29.0, "critical_hz": 25.0}


def rows(directory, name):
    path = os.path.join(directory, name)
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return list(csv.DictReader(f))


def num(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return float("nan")


def column(table, key):
    return [num(r[key]) for r in table]


def save(fig, directory, name, written):
    fig.tight_layout()
    fig.savefig(os.path.join(directory, name), dpi=90)
    plt.close(fig)
    written.append(name)


def bang_bang(d, written):
    strokes, samples = rows(d, "bang_bang.csv"), rows(d, "bang_bang_joints.csv")
    if not strokes or not samples:
        return
    joint = [k for k in samples[0] if k != "t"][0]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(11, 7))
    top.plot(column(samples, "t"), column(samples, joint), linewidth=0.7)
    lo, hi = num(strokes[0]["reference_low_rad"]), num(strokes[0]["reference_high_rad"])
    for level in (lo, hi):
        top.axhline(level, color="k", linestyle=":", linewidth=0.8)
    for r in strokes:
        top.axvline(num(r["start_s"]), color="grey", linewidth=0.5)
        top.text(num(r["start_s"]), hi, " %g Hz" % num(r["frequency_hz"]), fontsize=7, va="bottom")
    top.set_xlabel("time [s]")
    top.set_ylabel(joint + " [rad]")
    top.set_title("open-loop bang-bang of %s (dotted: extremes of the slow reference cycles)" % joint, fontsize=10)
    f, frac = column(strokes, "frequency_hz"), [100 * x for x in column(strokes, "fraction")]
    bottom.plot(f, frac, "o-", label="measured stroke")
    bottom.axhline(90, color="k", linestyle="--", linewidth=0.8, label="complete: 90 % of the range")
    bottom.axvline(THESIS["bang_bang_hz"], color="tab:red", linestyle="--", label="thesis: about 7 Hz")
    bound = num(strokes[0].get("bound_stroke_time_s"))
    if bound > 0:
        bottom.axvline(0.5 / bound, color="tab:green", linestyle=":", label="damping-limited (model) %.1f Hz" % (0.5 / bound))
    bottom.set_xlabel("bang-bang frequency [Hz]")
    bottom.set_ylabel("stroke [% of range]")
    bottom.set_ylim(0, 110)
    bottom.legend(fontsize=8)
    save(fig, d, "bang_bang.png", written)


def limit_to_limit(d, written):
    moves = rows(d, "limit_to_limit.csv")
    if not moves:
        return
    joints = []
    for r in moves:
        if r["joint"] not in joints:
            joints.append(r["joint"])
    fig, ax = plt.subplots(figsize=(max(6, 0.55 * len(joints) + 3), 4.5))
    width = 0.38
    for k, (kind, color) in enumerate((("flexion", "tab:blue"), ("extension", "tab:orange"))):
        xs, ts, bs = [], [], []
        for i, j in enumerate(joints):
            for r in moves:
                if r["joint"] == j and r["movement"] == kind:
                    xs.append(i + (k - 0.5) * width)
                    ts.append(1e3 * num(r["time_s"]))
                    bs.append(1e3 * num(r.get("bound_time_s")))
        ax.bar(xs, [0 if math.isnan(t) else t for t in ts], width, color=color, label=kind)
        ax.plot(xs, bs, "_", color="k", markersize=10, label="damping-limited (model)" if k == 0 else None)
    ax.axhline(THESIS["movement_ms"], color="tab:red", linestyle="--", label="thesis: about 70 ms")
    ax.set_xticks(range(len(joints)))
    ax.set_xticklabels(joints, rotation=60, fontsize=8)
    ax.set_ylabel("movement time to 90 % [ms]")
    ax.set_title("limit-to-limit sequence", fontsize=10)
    ax.legend(fontsize=8)
    save(fig, d, "limit_to_limit.png", written)


def reflex(d, written):
    trials, joints, acts = rows(d, "reflex.csv"), rows(d, "reflex_joints.csv"), rows(d, "reflex_actuators.csv")
    if not trials or not joints or not acts:
        return
    names = [k for k in joints[0] if k != "t"]
    disturbed, reacting = names[0], names[1]
    pressure = [k for k in acts[0] if k.startswith("p_") and k.endswith("_ext") and reacting in k][0]
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    tj, ta = column(joints, "t"), column(acts, "t")
    for i, tr in enumerate(trials):
        t1 = num(tr["detect_s"])
        if math.isnan(t1):
            continue
        c = "C%d" % i
        window = [(t - t1, r) for t, r in zip(tj, joints) if -0.1 <= t - t1 <= 0.1]
        axes[0].plot([1e3 * w[0] for w in window], [num(w[1][disturbed]) for w in window], color=c)
        axes[2].plot([1e3 * w[0] for w in window], [num(w[1][reacting]) for w in window], color=c,
                     label="trial %s: %.0f / %.0f ms" % (tr["trial"], 1e3 * num(tr["pressure_latency_s"]),
                                                         1e3 * num(tr["motion_latency_s"])))
        wa = [(t - t1, r) for t, r in zip(ta, acts) if -0.1 <= t - t1 <= 0.1]
        axes[1].plot([1e3 * w[0] for w in wa], [num(w[1][pressure]) / 1e3 for w in wa], ".-", color=c, markersize=3)
        axes[1].axvline(1e3 * num(tr["pressure_latency_s"]), color=c, linestyle=":", linewidth=0.8)
        axes[2].axvline(1e3 * num(tr["motion_latency_s"]), color=c, linestyle=":", linewidth=0.8)
    for ax in axes:
        ax.axvline(0, color="k", linewidth=0.8)
    axes[1].axvline(THESIS["pressure_ms"], color="tab:red", linestyle="--", label="thesis 8 ms")
    axes[2].axvline(THESIS["motion_ms"], color="tab:red", linestyle="--", label="thesis 29 ms")
    axes[0].set_ylabel(disturbed + " [rad]\n(disturbed)")
    axes[1].set_ylabel(pressure[2:] + " [kPa]")
    axes[2].set_ylabel(reacting + " [rad]\n(reacting)")
    axes[2].set_xlabel("time from the detecting sample [ms]")
    axes[0].set_title("reflex: disturbance detected at 0, first pressure change and first motion (dotted)", fontsize=10)
    axes[1].legend(fontsize=8)
    axes[2].legend(fontsize=8)
    save(fig, d, "reflex.png", written)


def step(d, written):
    steps, acts = rows(d, "step.csv"), rows(d, "step_actuators.csv")
    if not steps or not acts:
        return
    pressure = [k for k in acts[0] if k.startswith("p_")][0]
    ta, pa = column(acts, "t"), column(acts, pressure)
    fig, ax = plt.subplots(figsize=(9, 5))
    for i, s in enumerate(steps):
        t0 = num(s["step_s"])
        w = [(t - t0, p) for t, p in zip(ta, pa) if -0.02 <= t - t0 <= 0.15]
        ax.plot([1e3 * x[0] for x in w], [x[1] / 1e3 for x in w], ".-", markersize=3, color="C%d" % i,
                label="%+g -> %+g V: dead %.1f ms, tau %.1f ms" % (num(s["from_v"]), num(s["to_v"]),
                                                                   1e3 * num(s["dead_time_s"]),
                                                                   1e3 * num(s["time_constant_s"])))
    ax.axvline(0, color="k", linewidth=0.8)
    ax.set_xlabel("time from the step command [ms]")
    ax.set_ylabel(pressure[2:] + " [kPa abs]")
    ax.set_title("valve steps from either extreme (thesis 8.1: time constants around 20 ms)", fontsize=10)
    ax.legend(fontsize=8)
    save(fig, d, "step.png", written)


def chirp(d, written):
    points = rows(d, "chirp.csv")
    if not points:
        return
    fig, (mag, phase) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    keys = []
    for r in points:
        k = (r["offset_v"], r["amplitude_v"])
        if k not in keys:
            keys.append(k)
    for i, k in enumerate(keys):
        sel = [r for r in points if (r["offset_v"], r["amplitude_v"]) == k]
        f = column(sel, "frequency_hz")
        crit = num(sel[0]["critical_hz"])
        label = "%.2f +- %.2f V: -3 dB at %s" % (num(k[0]), num(k[1]), "%.1f Hz" % crit if not math.isnan(crit) else "n/a")
        mag.semilogx(f, column(sel, "gain_db"), ".-", color="C%d" % i, label=label)
        phase.semilogx(f, [math.degrees(x) for x in column(sel, "phase_rad")], ".-", color="C%d" % i)
        if not math.isnan(crit):
            mag.axvline(crit, color="C%d" % i, linestyle=":")
    mag.axhline(-3, color="k", linestyle="--", linewidth=0.8)
    mag.axvline(THESIS["critical_hz"], color="tab:red", linestyle="--", label="thesis: about 25 Hz")
    mag.set_ylabel("pressure gain [dB re low frequency]")
    mag.set_title("chirp of the valve command: chamber pressure response", fontsize=10)
    mag.legend(fontsize=8)
    phase.set_ylabel("phase [deg]")
    phase.set_xlabel("frequency [Hz]")
    save(fig, d, "chirp.png", written)


def main(directory):
    written = []
    for plot in (bang_bang, limit_to_limit, reflex, step, chirp):
        plot(directory, written)
    print("\n".join(written))


if __name__ == "__main__":
    main(sys.argv[1])
