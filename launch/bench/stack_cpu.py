#!/usr/bin/python3
"""Where the CPU goes when the simulated stack runs a task through roslaunch, and what the
behaviour MPC's optimiser is left with: sim.launch task:=<task> mode:=<mode> with each variant's
extra launch arguments, in alternating blocks of the same run (the machine is shared and noisy).

Each block is its own roslaunch on a random port. After a start-up, a probe finds every node's
process through the master (getPid), reads each thread's CPU time from /proc over the window and
sorts it by scheduling class (stack_run.StackCpu): SCHED_FIFO (command paths), normal at nice 0
(ROS plumbing, tools), and niced (the MPC's optimiser and its workers, nice 19). It also takes the MPC's iteration time
from its diagnostics. The table gives per variant and block the cores each node used, the
optimiser's share and the median iteration; stack_cpu.csv and stack_cpu.png go to --out.

Usage: stack_cpu.py [--task catch] [--mode pneumatic] [--variants "pool_manager:=false;pool_manager:=true"]
                    [--blocks 2] [--seconds 20] [--out DIR]
The first variant is the baseline; the RESULT lines: the last variant's stack without the MPC
(driver, pools, robot_state_publisher, master; the largest block, target half a core) and its
median iteration over the baseline's. Run it on an otherwise idle machine."""
import argparse
import csv
import os
import sys
import time

from stack_run import StackCpu, percentile, run_with_launch

STARTUP_S = 18.0


def probe(seconds):
    """Child process: CPU per node and class over the window, the MPC's iteration times; one JSON line."""
    import json

    import rospy
    from diagnostic_msgs.msg import DiagnosticArray

    rospy.init_node("stack_cpu_probe", anonymous=True, disable_signals=True)
    iterations = []
    recording = [False]

    def on_diag(msg):
        for s in msg.status:
            if s.name == "adroit_mpc" and recording[0]:
                value = float({kv.key: kv.value for kv in s.values}.get("time_total_ms", "0"))
                if value > 0:
                    iterations.append(value)

    rospy.Subscriber("/adroit/diagnostics", DiagnosticArray, on_diag, queue_size=20)
    time.sleep(STARTUP_S)
    cpu = StackCpu(rospy.get_name())
    cpu.start()
    recording[0] = True
    time.sleep(seconds)
    recording[0] = False
    print(json.dumps({"cores": cpu.stop(), "iteration_ms": iterations}), flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--probe", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--task", default="catch")
    parser.add_argument("--mode", default="pneumatic")
    parser.add_argument("--variants", default="pool_manager:=false;pool_manager:=true",
                        help="';'-separated variants, each a space-separated list of launch arguments")
    parser.add_argument("--blocks", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--out", default=".")
    args, rest = parser.parse_known_args()
    if args.probe:
        probe(float(rest[0]))
        return 0
    if args.blocks < 1 or args.seconds <= 0:
        print("stack_cpu: --blocks must be >= 1 and --seconds > 0", file=sys.stderr)
        return 2
    variants = [v.split() for v in args.variants.split(";")]
    os.makedirs(args.out, exist_ok=True)
    rows = []
    with open(os.path.join(args.out, "stack_cpu.log"), "w") as log:
        for block in range(args.blocks):
            for vi, variant in enumerate(variants):
                launch = ["adroit_launch", "sim.launch", "task:=" + args.task, "mode:=" + args.mode] + variant
                result = run_with_launch(launch, [args.seconds], STARTUP_S + args.seconds + 60, log)
                rows.append((block, vi, result))
    label = [" ".join(v) or "(defaults)" for v in variants]
    nodes = sorted(set(n for _, _, r in rows for n in r["cores"]))
    print("CPU of the stack, sim.launch task:=%s mode:=%s, %d s windows, cores used (of %d)" %
          (args.task, args.mode, args.seconds, os.cpu_count()))
    with open(os.path.join(args.out, "stack_cpu.csv"), "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["block", "variant", "node", "class", "cores"])
        for block, vi, r in rows:
            print("\nblock %d, %s: MPC iteration median %.0f ms (%d samples)" %
                  (block, label[vi], percentile(r["iteration_ms"], 0.5), len(r["iteration_ms"])))
            for node in nodes:
                classes = r["cores"].get(node, {})
                if sum(classes.values()) >= 0.005:
                    print("  %-28s %5.2f  (%s)" % (node, sum(classes.values()),
                                                  ", ".join("%s %.2f" % kv for kv in sorted(classes.items()))))
                for cls, value in classes.items():
                    out.writerow([block, label[vi], node, cls, "%.4f" % value])
            by_class = {}
            for classes in r["cores"].values():
                for cls, value in classes.items():
                    by_class[cls] = by_class.get(cls, 0.0) + value
            print("  by class: " + ", ".join("%s %.2f" % kv for kv in sorted(by_class.items())))
    print("\nvariant                          optimiser cores   MPC iteration ms (median of each block)")
    medians = []
    for vi in range(len(variants)):
        runs = [r for _, v, r in rows if v == vi]
        opt = [sum(c.get("niced", 0.0) for c in r["cores"].values()) for r in runs]
        its = [percentile(r["iteration_ms"], 0.5) for r in runs]
        medians.append(percentile(its, 0.5))
        print("  %-30s %s   %s" % (label[vi], " ".join("%.2f" % o for o in opt), " ".join("%.0f" % i for i in its)))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(9, 4.5))
        width = 0.8 / len(rows)
        for k, (block, vi, r) in enumerate(rows):
            values = [sum(r["cores"].get(n, {}).values()) for n in nodes]
            ax.bar([i + k * width for i in range(len(nodes))], values, width,
                   label="%s, block %d: MPC %.0f ms" % (label[vi], block, percentile(r["iteration_ms"], 0.5)))
        ax.set_xticks([i + 0.4 - width / 2 for i in range(len(nodes))])
        ax.set_xticklabels(nodes, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel("cores used")
        ax.set_title("sim.launch task:=%s mode:=%s: CPU per node" % (args.task, args.mode))
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(os.path.join(args.out, "stack_cpu.png"), dpi=100)
    except ImportError:
        print("stack_cpu: python3-matplotlib missing, no plot", file=sys.stderr)
    # The stack without the behaviour MPC (driver, pools, robot_state_publisher, master): its
    # budget is half a core, so the optimiser keeps the rest of the machine (issue 38).
    stack = [sum(sum(c.values()) for n, c in r["cores"].items() if n != "adroit_mpc")
             for _, v, r in rows if v == len(variants) - 1]
    print("\nstack without the MPC, %s: %s cores (blocks)" % (label[-1], " ".join("%.2f" % x for x in stack)))
    worst = max(stack)
    print("RESULT adroit_launch/%s_%s_stack_without_mpc_cores %.2f cores target <= 0.5 %s" %
          (args.task, args.mode, worst, "PASS" if worst <= 0.5 else "FAIL"))
    if len(variants) > 1 and medians[0] > 0:
        ratio = medians[-1] / medians[0]
        print("RESULT adroit_launch/%s_%s_mpc_iteration_ratio %.2f ratio target <= 1.0 %s" %
              (args.task, args.mode, ratio, "PASS" if ratio <= 1.0 else "FAIL"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
