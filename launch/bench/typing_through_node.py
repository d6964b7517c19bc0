#!/usr/bin/python3
"""Typing through the node, as a user runs it: `roslaunch adroit_launch sim.launch task:=type
mode:=<mode>` in real time on this machine (the driver, the behaviour MPC and, in pneumatic
mode, the five pools share its cores), then random 10-digit sequences on /adroit/mpc/type.

Per mode, in its own roslaunch: after a start-up, `--idle` seconds without a sequence (a key
registered then was typed unasked), then each sequence, given 1.55 s per key (mpc_success allows
1.5) or until the node reports it done. Keys right: the sequence's keys typed in order, after
replaying the backspaces, as mpc_success counts them; wrong presses: presses of a key other than
the one expected next, a wrong key later backspaced included (presses_and_wrong, as the typing task
counts them and mpc_success reports them). The MPC's iteration time and policy age
are the node's diagnostics. Writes typing_through_node.csv and .png to --out; ends with RESULT
lines. mpc_success measures the planner with the cores to itself; this is the node beside the
driver and the pools.

Usage: typing_through_node.py [--modes force,pneumatic] [--sequences 3] [--idle 20] [--seed 1] [--out DIR]
Run it on an otherwise idle machine."""
import argparse
import csv
import os
import random
import sys
import time

from stack_run import percentile, run_with_launch

STARTUP_S = 8.0
PER_KEY_S = 1.55


def keys_right(typed, sequence):
    """Keys of the sequence typed in order once each backspace has removed the key before it."""
    text = []
    for key in typed:
        if key == "bs":
            if text:
                text.pop()
        else:
            text.append(key)
    right = 0
    for got, want in zip(text, sequence):
        if got != want:
            break
        right += 1
    return right


def presses_and_wrong(typed, sequence):
    """(presses, wrong presses) as the typing task counts them (TypeTask::presses, wrongPresses):
    every key is a press; a press is wrong when it is not the key expected next with the
    auto-correction replayed (after a wrong key backspace is expected, then the intended key).
    A wrong key later removed by backspace stays a wrong press; the backspace removing it is not
    one, a backspace deleting a right key or nothing is."""
    matched = pending = wrong = 0
    for key in typed:
        expected = "bs" if pending else (sequence[matched] if matched < len(sequence) else None)
        if key == expected:
            if pending:
                pending -= 1
            else:
                matched += 1
            continue
        wrong += 1
        if key == "bs":
            matched = max(matched - 1, 0)  # deletes a right key, or nothing
        else:
            pending += 1
    return len(typed), wrong


def wrong_percent(presses, wrong):
    """Wrong presses in % of all presses (0 without a press)."""
    return 100.0 * wrong / presses if presses else 0.0


def probe(idle, sequences_arg):
    import json
    import threading

    import rospy
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import String

    rospy.init_node("typing_probe", anonymous=True, disable_signals=True)
    lock = threading.Lock()
    typed, events, mpc = [], [], []

    def on_typed(msg):
        with lock:
            typed.append((time.time(), msg.data))

    def on_event(msg):
        with lock:
            events.append((time.time(), msg.data))

    def on_diag(msg):
        for s in msg.status:
            if s.name == "adroit_mpc":
                v = {kv.key: kv.value for kv in s.values}
                with lock:
                    mpc.append((float(v.get("time_total_ms", "nan")), float(v.get("policy_age_mean_ms", "nan"))))

    rospy.Subscriber("/adroit/mpc/typed", String, on_typed, queue_size=100)
    rospy.Subscriber("/adroit/mpc/events", String, on_event, queue_size=100)
    rospy.Subscriber("/adroit/diagnostics", DiagnosticArray, on_diag, queue_size=20)
    pub = rospy.Publisher("/adroit/mpc/type", String, queue_size=1, latch=True)
    time.sleep(STARTUP_S)
    start = time.time()
    time.sleep(idle)
    with lock:
        unasked = [k for t, k in typed if t >= start]
        mpc_from = len(mpc)
    results = []
    for sequence in sequences_arg.split(","):
        t0 = time.time()
        pub.publish(String(data=sequence))
        deadline = t0 + PER_KEY_S * len(sequence)
        done_at = None
        while time.time() < deadline and done_at is None:
            with lock:
                done_at = next((t for t, e in events if t >= t0 and e.startswith("done")), None)
            time.sleep(0.05)
        with lock:  # the keys, and the node's events (s after the sequence) to read a failed run afterwards
            got = [k for t, k in typed if t >= t0]
            seen = [[round(t - t0, 3), e] for t, e in events if t >= t0]
        right = keys_right(got, sequence)
        presses, wrong = presses_and_wrong(got, sequence)
        results.append({"sequence": sequence, "typed": got, "right": right, "presses": presses, "wrong": wrong,
                        "seconds": (done_at or time.time()) - t0, "done": done_at is not None, "events": seen})
        time.sleep(1.0)  # the hand settles before the next sequence
    with lock:
        iteration = [a for a, _ in mpc[mpc_from:]]
        age = [b for _, b in mpc[mpc_from:]]
    print(json.dumps({"unasked": unasked, "sequences": results, "iteration_ms": iteration, "policy_age_ms": age}),
          flush=True)


def main():
    if len(sys.argv) == 4 and sys.argv[1] == "--probe":
        return probe(float(sys.argv[2]), sys.argv[3])
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--modes", default="force,pneumatic")
    ap.add_argument("--sequences", type=int, default=3)
    ap.add_argument("--idle", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--out", default=os.path.join(os.environ.get("ROS_HOME", "/tmp"), "typing_through_node"))
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    rng = random.Random(args.seed)
    sequences = ["".join(rng.choice("0123456789") for _ in range(10)) for _ in range(args.sequences)]
    rows, summary = [], []
    with open(os.path.join(args.out, "launch.log"), "w") as log:
        for mode in args.modes.split(","):
            timeout = STARTUP_S + args.idle + len(sequences) * (PER_KEY_S * 10 + 2) + 120
            r = run_with_launch(["adroit_launch", "sim.launch", "task:=type", "mode:=" + mode],
                                [args.idle, ",".join(sequences)], timeout, log)
            right = sum(s["right"] for s in r["sequences"])
            total = sum(len(s["sequence"]) for s in r["sequences"])
            seconds = sum(s["seconds"] for s in r["sequences"])
            presses = sum(s["presses"] for s in r["sequences"])
            wrong = sum(s["wrong"] for s in r["sequences"])
            summary.append((mode, len(r["unasked"]), right, total, 60.0 * right / max(seconds, 1e-9),
                            percentile(r["iteration_ms"], 0.5), percentile(r["policy_age_ms"], 0.5), presses, wrong))
            for s in r["sequences"]:
                rows.append([mode, s["sequence"], " ".join(s["typed"]), s["right"], len(s["sequence"]),
                             s["presses"], s["wrong"], "%.2f" % s["seconds"], s["done"]])
                print("%s: %s -> %s (%d right, %d of %d presses wrong, %.1f s%s)" % (
                    mode, s["sequence"], " ".join(s["typed"]), s["right"], s["wrong"], s["presses"], s["seconds"],
                    ", done" if s["done"] else ""), flush=True)
    print("\n== typing through the node (sim.launch task:=type), %d sequences of 10 digits, %.0f s idle first =="
          % (len(sequences), args.idle))
    print("%-10s %14s %12s %20s %10s %18s %16s" % ("mode", "typed unasked", "keys right", "wrong presses",
                                                   "keys/min", "MPC iteration ms", "policy age ms"))
    for mode, unasked, right, total, per_min, it, age, presses, wrong in summary:
        print("%-10s %14d %8d/%-3d %8d/%-4d (%3.0f %%) %10.0f %18.1f %16.1f" % (
            mode, unasked, right, total, wrong, presses, wrong_percent(presses, wrong), per_min, it, age))
    with open(os.path.join(args.out, "typing_through_node.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["mode", "sequence", "typed", "right", "keys", "presses", "wrong_presses", "seconds", "done"])
        w.writerows(rows)
    plot(summary, os.path.join(args.out, "typing_through_node.png"))
    for mode, unasked, right, total, per_min, it, age, presses, wrong in summary:
        rate = right / total
        print("RESULT adroit_launch/typing_node_keys_correct_rate_%s %.2f ratio target >= 0.9 %s" %
              (mode, rate, "PASS" if rate >= 0.9 else "FAIL"))
        print("RESULT adroit_launch/typing_node_unasked_keys_%s %d count target == 0 %s" %
              (mode, unasked, "PASS" if unasked == 0 else "FAIL"))
        percent = wrong_percent(presses, wrong)
        print("RESULT adroit_launch/typing_node_wrong_press_percent_%s %.1f %% target <= 10 %s" %
              (mode, percent, "PASS" if percent <= 10 else "FAIL"))


def plot(summary, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.2))
    modes = [s[0] for s in summary]
    ax.bar(modes, [s[2] / s[3] for s in summary], color="tab:blue", label="keys right")
    for i, s in enumerate(summary):
        ax.text(i, s[2] / s[3] + 0.02, "%d/%d, %d unasked\n%.0f ms iteration" % (s[2], s[3], s[1], s[5]),
                ha="center", fontsize=8)
    ax.axhline(0.9, color="r", linestyle="--", label="90 %")
    ax.set_ylim(0, 1.25)
    ax.set_ylabel("fraction of keys right")
    ax.set_title("Typing through the node (sim.launch task:=type)", fontsize=9)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()
