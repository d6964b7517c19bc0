#!/usr/bin/python3
"""The behaviours through the launch files, as a user runs them on this machine: the demo's catch
(demo.launch with demo_report, as scripts/demo.sh), relocation (sim.launch task:=relocate: the
ball let go into the hand, the goal given through /adroit/mpc/set_task 1 s later) and typing
(sim.launch task:=type, typing_through_node.py's probe), each run --runs times, every run its
own roslaunch on a random port (behaviour_probes.py has what a run does).

Per run: success (catch: CAUGHT; relocation: the ball within 3 cm of the goal 3 s after it was
given; typing: keys right of 10, wrong presses, keys typed unasked in the idle period before the
sequence), the MPC's iteration time and policy age (medians of its diagnostics over the run's
window), the CPU of each node of the stack over the window (driver, pools, robot_state_publisher,
master, MPC) and machine_slowdown beside it. The draws are seeded: relocation as mpc_success
(released 4-9 cm above the hold position, +-1.5 cm sideways; goal at least 5 cm from the hold,
x +-8, y +-6, z -10..0 cm), one random 10-digit sequence per typing run.

The table's last columns: machine_slowdown's share of the window at half speed or worse (slow
%), its longest stall (ms), the driver's watchdog trips and the 1-minute load average at the
window's end (machine_slowdown under SCHED_FIFO 99 sees the machine's own speed, not how busy
its cores are: the load shows other work beside the run).

Prints a table per task and the totals, writes behaviour_through_launch.csv (one row per run),
behaviour_through_launch_cpu.csv (per node and scheduling class) and behaviour_through_launch.png
to --out, and ends with RESULT lines (targets scaled to --runs: catch 90 %, relocation 80 %,
typing 90 % of the keys and no key unasked), each followed by machine_slowdown over its runs.

Usage: behaviour_through_launch.py [--tasks catch,relocate,type] [--runs 10] [--mode pneumatic]
                                   [--planner ilqg] [--seed 1] [--idle 10] [--out DIR]
Run it on an otherwise idle machine."""
import argparse
import csv
import json
import math
import os
import random
import subprocess
import sys

from stack_run import percentile, run_with_launch

TASKS = ("catch", "relocate", "type")
MODES = ("pneumatic", "force")
PLANNERS = ("ilqg", "sampling", "cem")
GROUPS = (("driver", ("adroit_sim", "adroit_hw")), ("pools", ("pool",)), ("rsp", ("robot_state_publisher",)),
          ("master", ("rosmaster",)), ("mpc", ("adroit_mpc",)))
GROUP_NAMES = [g for g, _ in GROUPS] + ["other"]
TIMEOUT_S = {"catch": 200.0, "relocate": 150.0, "type": 150.0}  # + the idle period for typing


class ArgumentError(Exception):
    pass


class Parser(argparse.ArgumentParser):
    def error(self, message):
        raise ArgumentError(message)


def parse_args(argv):
    """The options, checked; ArgumentError with a one-line reason otherwise."""
    ap = Parser(prog="behaviour_through_launch.py", description=__doc__.split("\n")[0])
    ap.add_argument("--tasks", default=",".join(TASKS))
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--mode", default="pneumatic")
    ap.add_argument("--planner", default="ilqg")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--idle", type=float, default=10.0, help="typing: seconds without a sequence first")
    ap.add_argument("--out", default=os.path.join(os.environ.get("ROS_HOME", "/tmp"), "behaviour_through_launch"))
    args = ap.parse_args(argv)
    args.tasks = args.tasks.split(",")
    for task in args.tasks:
        if task not in TASKS:
            raise ArgumentError("--tasks: unknown task '%s' (known: %s)" % (task, ", ".join(TASKS)))
    if len(set(args.tasks)) != len(args.tasks):
        raise ArgumentError("--tasks: a task named twice")
    if args.runs < 1:
        raise ArgumentError("--runs must be >= 1")
    if args.mode not in MODES:
        raise ArgumentError("--mode: '%s', expected %s" % (args.mode, " or ".join(MODES)))
    if args.planner not in PLANNERS:
        raise ArgumentError("--planner: '%s', expected one of %s" % (args.planner, ", ".join(PLANNERS)))
    if not 0 <= args.idle <= 600:
        raise ArgumentError("--idle must be in [0, 600] s")
    return args


def relocate_offsets(seed, n):
    """Per run (start, goal) relative to the hold position (m), as mpc_success draws them."""
    rng = random.Random("%d:relocate" % seed)
    trials = []
    for _ in range(n):
        u = lambda: rng.uniform(-1, 1)  # noqa: E731
        start = (0.015 * u(), 0.015 * u(), 0.065 + 0.025 * u())
        goal = (0, 0, 0)
        while math.hypot(*goal) < 0.05:  # beyond the success radius of the hold by at least 2 cm
            goal = (0.08 * u(), 0.06 * u(), -0.05 + 0.05 * u())
        trials.append((start, goal))
    return trials


def type_sequences(seed, n):
    rng = random.Random("%d:type" % seed)
    return ["".join(rng.choice("0123456789") for _ in range(10)) for _ in range(n)]


def launch_args(task, run, args):
    if task == "catch":  # the demo: the driver starts paused, demo_report starts it
        return ["adroit_launch", "demo.launch", "mode:=" + args.mode, "planner:=" + args.planner]
    return ["adroit_launch", "sim.launch", "task:=" + task, "mode:=" + args.mode, "planner:=" + args.planner,
            "seed:=%d" % (args.seed + run)]


def group_of(node):
    """The stack's part a node (its name without namespace, e.g. adroit/pool_manager) belongs to."""
    base = node.rsplit("/", 1)[-1]
    for group, prefixes in GROUPS:
        if any(base.startswith(p) for p in prefixes):
            return group
    return "other"


def group_cores(cores):
    """{node: {class: cores}} -> {group: cores} over GROUP_NAMES."""
    out = dict.fromkeys(GROUP_NAMES, 0.0)
    for node, classes in cores.items():
        out[group_of(node)] += sum(classes.values())
    return out


def run_row(task, run, r):
    """One run's probe result as a flat CSV row."""
    row = {"task": task, "run": run + 1, "success": bool(r.get("success")), "error": r.get("error", "")}
    for key in ("distance_cm", "from_hold_cm", "keys_right", "keys", "presses", "wrong_presses", "unasked",
                "watchdog_trips", "safe_state", "window_s", "stall_ms", "load_average"):
        row[key] = r.get(key)
    row["iteration_ms"] = percentile(r.get("iteration_ms", []), 0.5)
    row["policy_age_ms"] = percentile(r.get("policy_age_ms", []), 0.5)
    row.update(group_cores(r.get("cores", {})))
    row["stack_without_mpc"] = sum(row[g] for g in GROUP_NAMES if g != "mpc")
    fraction = r.get("slowdown_fraction")
    row["slowdown_percent"] = None if fraction is None else 100 * fraction
    return row


def median_of(rows, key):
    return percentile([r[key] for r in rows if r[key] is not None and not math.isnan(r[key])], 0.5)


def summarise(task, rows, slow_fraction):
    """The task's totals over its runs; a run counts as slowed when machine_slowdown saw the machine
    at half speed or worse for more than slow_fraction of its window (machine_probe.SLOW_FRACTION)."""
    s = {"task": task, "runs": len(rows), "successes": sum(r["success"] for r in rows), "slow_fraction": slow_fraction}
    for key in ("iteration_ms", "policy_age_ms", "stack_without_mpc", "mpc", "slowdown_percent"):
        s[key] = median_of(rows, key)
    slow = [r["slowdown_percent"] for r in rows if r["slowdown_percent"] is not None]
    s["slowdown_worst"] = max(slow) if slow else float("nan")
    s["slowed_runs"] = sum(1 for p in slow if p > 100 * slow_fraction)
    s["stall_ms"] = max([r["stall_ms"] for r in rows if r["stall_ms"] is not None], default=float("nan"))
    if task == "type":
        s["keys_right"] = sum(r["keys_right"] or 0 for r in rows)
        s["keys"] = sum(r["keys"] or 10 for r in rows)  # a run without a result counts its 10 keys missed
        s["unasked"] = sum(r["unasked"] or 0 for r in rows)
        s["wrong_presses"] = sum(r["wrong_presses"] or 0 for r in rows)
        s["presses"] = sum(r["presses"] or 0 for r in rows)
    return s


def figure_suffix(mode, planner):
    """The RESULT names are the required figures' (pneumatic, iLQG); other settings are named."""
    return ("" if mode == "pneumatic" else "_" + mode) + ("" if planner == "ilqg" else "_" + planner)


def verdict(ok):
    return "PASS" if ok else "FAIL"


def result_lines(summaries, mode, planner):
    """RESULT lines (DESIGN.md section 5), each task's followed by machine_slowdown over its runs."""
    suffix, lines = figure_suffix(mode, planner), []
    names = {"catch": ("demo_catch_successes", 0.9), "relocate": ("relocate_successes", 0.8)}
    for s in summaries:
        if s["task"] in names:
            name, fraction = names[s["task"]]
            target = math.ceil(fraction * s["runs"] - 1e-9)
            lines.append("RESULT adroit_launch/%s%s %d of %d target >= %d %s" % (
                name, suffix, s["successes"], s["runs"], target, verdict(s["successes"] >= target)))
        else:
            percent = 100.0 * s["keys_right"] / s["keys"] if s["keys"] else 0.0
            lines.append("RESULT adroit_launch/type_%s_keys_right_percent%s %.1f %% target >= 90 %s" % (
                mode, "" if planner == "ilqg" else "_" + planner, percent, verdict(percent >= 90)))
            lines.append("RESULT adroit_launch/type_unasked_keys%s %d keys target <= 0 %s" % (
                suffix, s["unasked"], verdict(s["unasked"] <= 0)))
        lines.append("  machine_slowdown beside the %s runs: %.1f %% of the time over 2x (median of the runs, worst "
                     "%.1f %%), longest stall %.0f ms; %d of %d runs with the machine at half speed > %.0f %% of the "
                     "time" % (s["task"], s["slowdown_percent"], s["slowdown_worst"], s["stall_ms"], s["slowed_runs"],
                               s["runs"], 100 * s["slow_fraction"]))
    return lines


def outcome(task, row):
    if row["error"] and not row["success"]:
        return "error"
    if task == "catch":
        return ("CAUGHT" if row["success"] else "dropped") + (
            " %.1f cm" % row["distance_cm"] if row["distance_cm"] is not None else "")
    if task == "relocate":  # and where the ball was when the goal came: still held after the catch?
        return ("at goal" if row["success"] else "missed") + fmt(row["distance_cm"], " %.1f cm") + fmt(
            row["from_hold_cm"], " (%.1f from hold at goal)")
    wrong = "" if row["wrong_presses"] is None else ", %d wrong" % row["wrong_presses"]
    return "%d/%d keys%s, %d unasked" % (row["keys_right"], row["keys"], wrong, row["unasked"])


def fmt(value, spec):
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else spec % value


def print_task(task, rows, s, args):
    print("\n== %s through %s mode:=%s planner:=%s, %d runs ==" % (
        task, "demo.launch" if task == "catch" else "sim.launch task:=" + task, args.mode, args.planner, len(rows)))
    print("%4s %-40s %7s %6s | %6s %6s %6s %6s %6s %6s | %6s %5s %5s %5s" % (
        "run", "outcome", "iter ms", "age ms", *GROUP_NAMES, "slow %", "stall", "trips", "load"))
    for r in rows:
        print("%4d %-40s %7s %6s | %s | %6s %5s %5s %5s" % (
            r["run"], outcome(task, r)[:40], fmt(r["iteration_ms"], "%.1f"), fmt(r["policy_age_ms"], "%.0f"),
            " ".join("%6.2f" % r[g] for g in GROUP_NAMES), fmt(r["slowdown_percent"], "%.1f"),
            fmt(r["stall_ms"], "%.0f"), fmt(r["watchdog_trips"], "%d"), fmt(r["load_average"], "%.1f")))
        if r["error"]:
            print("     %s" % r["error"][:300].replace("\n", " "))
    if task == "type":
        head = "%d of %d keys right, %d of %d presses wrong, %d typed unasked" % (
            s["keys_right"], s["keys"], s["wrong_presses"], s["presses"], s["unasked"])
    else:
        head = "%d of %d %s" % (s["successes"], s["runs"], "caught" if task == "catch" else "at the goal")
    print("%s: %s; medians over the runs: MPC iteration %s ms, policy age %s ms, stack without the MPC %s cores, "
          "MPC %s cores" % (task, head, fmt(s["iteration_ms"], "%.1f"), fmt(s["policy_age_ms"], "%.0f"),
                            fmt(s["stack_without_mpc"], "%.2f"), fmt(s["mpc"], "%.2f")))


def run_task(task, args, log, cpu_rows):
    """Every run of a task; its rows."""
    draws = {"relocate": relocate_offsets(args.seed, args.runs), "type": type_sequences(args.seed, args.runs)}
    rows = []
    for run in range(args.runs):
        params = {"mode": args.mode}
        if task == "relocate":
            params["start"], params["goal"] = draws["relocate"][run]
        elif task == "type":
            params.update(sequence=draws["type"][run], idle=args.idle)
        log.write("\n==== %s run %d: %s ====\n" % (task, run + 1, json.dumps(params)))
        log.flush()
        try:
            r = run_with_launch(launch_args(task, run, args), [task, json.dumps(params)],
                                TIMEOUT_S[task] + args.idle, log)
        except (RuntimeError, subprocess.TimeoutExpired) as e:
            r = {"error": str(e)}
        rows.append(run_row(task, run, r))
        if not rows[-1]["success"]:  # what the node reported, for reading the failure afterwards
            log.write("==== %s run %d failed: %s\n" % (task, run + 1, json.dumps(
                {k: r.get(k) for k in ("error", "typed", "events", "unasked_keys", "end", "goal") if k in r})))
            log.flush()
        for node, classes in sorted(r.get("cores", {}).items()):
            for cls, value in sorted(classes.items()):
                cpu_rows.append([task, run + 1, node, cls, "%.4f" % value])
        print("%s run %d: %s, MPC iteration %s ms" % (task, run + 1, outcome(task, rows[-1]),
                                                      fmt(rows[-1]["iteration_ms"], "%.1f")), flush=True)
    return rows


def plot(rows, summaries, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax0, ax1, ax2) = plt.subplots(1, 3, figsize=(14, 4.2), gridspec_kw={"width_ratios": [1, 1.6, 1.6]})
    targets = {"catch": 0.9, "relocate": 0.8, "type": 0.9}
    for i, s in enumerate(summaries):
        k, n = (s["keys_right"], s["keys"]) if s["task"] == "type" else (s["successes"], s["runs"])
        ax0.bar(i, k / n, color="tab:blue")
        ax0.text(i, k / n + 0.02, "%d/%d" % (k, n), ha="center", fontsize=8)
        ax0.plot([i - 0.4, i + 0.4], [targets[s["task"]]] * 2, "r--")
    ax0.set_xticks(range(len(summaries)))
    ax0.set_xticklabels(["catch" if s["task"] == "catch" else "relocate" if s["task"] == "relocate"
                         else "type (keys)" for s in summaries])
    ax0.set_ylim(0, 1.15)
    ax0.set_ylabel("success (typing: keys right)")
    ax0.set_title("success per task (- - target)", fontsize=9)
    labels = ["%s%d" % (r["task"][0], r["run"]) for r in rows]
    x = range(len(rows))
    ax1.plot(x, [r["iteration_ms"] for r in rows], "o", label="MPC iteration (median)")
    ax1.plot(x, [r["policy_age_ms"] for r in rows], "s", mfc="none", label="policy age (median)")
    ax1.set_ylabel("ms")
    ax1.set_ylim(bottom=0)
    ax1.set_title("MPC iteration time and policy age per run", fontsize=9)
    ax1.legend(fontsize=8)
    bottom = [0.0] * len(rows)
    for g in GROUP_NAMES:
        ax2.bar(x, [r[g] for r in rows], bottom=bottom, label=g)
        bottom = [b + r[g] for b, r in zip(bottom, rows)]
    ax2.set_ylabel("cores used (of %d)" % os.cpu_count())
    ax2.set_ylim(0, max([os.cpu_count()] + bottom) * 1.05)
    ax2.set_title("the stack's CPU per run (the MPC's optimiser is niced)", fontsize=9)
    ax2.legend(fontsize=7, ncol=3, loc="upper right")
    for ax in (ax1, ax2):
        ax.set_xticks(list(x))
        ax.set_xticklabels(labels, fontsize=7, rotation=90 if len(rows) > 15 else 0)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def write_csv(path, header, rows):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)


def main(argv):
    if len(argv) == 3 and argv[0] == "--probe":
        from behaviour_probes import probe
        return probe(argv[1], json.loads(argv[2]))
    try:
        args = parse_args(argv)
    except ArgumentError as e:
        print("behaviour_through_launch: %s" % e, file=sys.stderr)
        return 2
    import rospkg
    sys.path.insert(0, os.path.join(rospkg.RosPack().get_path("adroit_core"), "tools"))
    import machine_probe
    os.makedirs(args.out, exist_ok=True)
    rows, summaries, cpu_rows = [], [], []
    with open(os.path.join(args.out, "behaviour_through_launch.log"), "w") as log:
        for task in args.tasks:
            task_rows = run_task(task, args, log, cpu_rows)
            rows += task_rows
            summaries.append(summarise(task, task_rows, machine_probe.SLOW_FRACTION))
    for s in summaries:
        print_task(s["task"], [r for r in rows if r["task"] == s["task"]], s, args)
    header = list(rows[0].keys())
    write_csv(os.path.join(args.out, "behaviour_through_launch.csv"), header,
              [["%.4g" % r[k] if isinstance(r[k], float) else r[k] for k in header] for r in rows])
    write_csv(os.path.join(args.out, "behaviour_through_launch_cpu.csv"), ["task", "run", "node", "class", "cores"],
              cpu_rows)
    plot(rows, summaries, os.path.join(args.out, "behaviour_through_launch.png"))
    print("\nwritten: %s/behaviour_through_launch.{csv,png}, behaviour_through_launch_cpu.csv, the launches' "
          "output in behaviour_through_launch.log\n" % args.out)
    for line in result_lines(summaries, args.mode, args.planner):
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
