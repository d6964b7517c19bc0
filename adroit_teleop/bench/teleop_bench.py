#!/usr/bin/python3
"""Teleop benchmark: glove-to-physics latency and the sustained glove rate, end to end with
the glove emulator (roslaunch adroit_launch teleop.launch, force mode, real time).

  latency = first physics step acting on a command (the driver's /adroit/command_latency)
            - the glove record's arrival on the serial line (the glove node's stamp, which
              the teleop node's command carries)
  serial  = that arrival - the emulator's write() of the record (its --log), reported apart

Baseline, same run: a command published straight to the driver from this (rospy) script,
stamped when published, goes through the last hop only (ROS to the driver, then the wait for
the next 2 ms physics step). Structural floor: a command arriving at a random phase waits U(0, 2 ms) for the next
step (p50 1 ms, p99 2 ms). A demonstration is recorded with rosbag during the run and
plotted with `demos plot`.

usage: teleop_bench.py [--seconds S] [--rate HZ] [--out DIR]
Writes DIR/latency.csv, DIR/latency.png, DIR/demo_*.bag, DIR/demonstration.png; ends with
RESULT lines.
"""
import argparse
import csv
import glob
import os
import signal
import subprocess
import sys
import threading
import time

import rospy
from adroit_msgs.msg import CommandLatency, GloveSensors, TendonForceCommand
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

STEP = 0.002  # the driver's physics step (s)


def percentile(values, q):
    s = sorted(values)
    return s[min(len(s) - 1, int(q * (len(s) - 1) + 0.5))] if s else float("nan")


def result(name, value, unit, op, target):
    ok = value <= target if op == "<=" else value >= target
    print("RESULT adroit_teleop/%s %.4g %s target %s %g %s" % (name, value, unit, op, target, "PASS" if ok else "FAIL"))


class Collector:
    def __init__(self):
        self.lock = threading.Lock()
        self.phase = None
        self.latency = {"pipeline": [], "baseline": []}
        self.glove = []  # (record, stamp, raw)
        rospy.Subscriber("/adroit/command_latency", CommandLatency, self.on_latency, queue_size=1000)
        rospy.Subscriber("/adroit_teleop/glove", GloveSensors, self.on_glove, queue_size=1000)

    def on_latency(self, msg):
        with self.lock:
            if self.phase in self.latency:
                self.latency[self.phase].append(msg.latency)

    def on_glove(self, msg):
        with self.lock:
            if self.phase == "pipeline":
                self.glove.append((msg.record, msg.header.stamp.to_sec(), bytes(msg.raw)))


def serial_transit(glove, log_path):
    """Arrival - write() per record, matched on the sensor values near the same record number."""
    writes = []
    with open(log_path) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            parts = line.split()
            writes.append((int(parts[1]) * 1e-9, bytes(int(v) for v in parts[2:])))
    transit = []
    by_values = {}
    for t, values in writes:
        by_values.setdefault(values, []).append(t)
    for _, stamp, raw in glove:
        candidates = [t for t in by_values.get(raw, []) if 0 <= stamp - t < 0.05]
        if candidates:
            transit.append(stamp - max(candidates))
    return transit


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="of each phase")
    parser.add_argument("--rate", type=float, default=150.0, help="glove records per second (100-150)")
    parser.add_argument("--out", default=os.path.expanduser("~/.ros/adroit_teleop_bench"))
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    for old in glob.glob(os.path.join(args.out, "demo_*.bag*")):
        os.remove(old)
    port = "/tmp/adroit_glove_bench_%d" % os.getpid()
    glove_log = os.path.join(args.out, "glove_writes.log")
    launch = subprocess.Popen(
        ["roslaunch", "adroit_launch", "teleop.launch", "port:=" + port, "emulator_rate:=%g" % args.rate,
         "emulator_args:=--log " + glove_log, "record:=true", "bag_prefix:=" + os.path.join(args.out, "demo")],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        rospy.init_node("teleop_bench", disable_signals=True)
        rec = Collector()
        deadman = rospy.Publisher("/adroit_teleop/deadman", Bool, queue_size=1, latch=True)
        direct = rospy.Publisher("/adroit/tendon_force_command", TendonForceCommand, queue_size=10,
                                 tcp_nodelay=True)
        joints = rospy.wait_for_message("/adroit/joint_states", JointState, timeout=60)
        rospy.wait_for_message("/adroit_teleop/glove", GloveSensors, timeout=60)
        time.sleep(2.0)

        # Baseline: min-tension commands straight to the driver, stamped when published.
        cylinders = 40
        command = TendonForceCommand(index=list(range(cylinders)), force=[0.3] * cylinders)
        with rec.lock:
            rec.phase = "baseline"
        end = time.monotonic() + args.seconds
        while time.monotonic() < end:
            command.header.stamp = rospy.Time.now()
            direct.publish(command)
            time.sleep(1.0 / args.rate)
        # Pipeline: the dead-man pressed, the glove moves the hand (the teleop node takes over
        # within a glove period, inside the driver's 50 ms watchdog).
        with rec.lock:
            rec.phase = "pipeline"
        deadman.publish(Bool(True))
        time.sleep(args.seconds)
        with rec.lock:
            rec.phase = None
        deadman.publish(Bool(False))
        time.sleep(0.5)
    finally:
        os.killpg(launch.pid, signal.SIGINT)  # rosbag record writes a valid bag on SIGINT
        try:
            launch.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(launch.pid, signal.SIGKILL)

    pipeline, baseline = rec.latency["pipeline"], rec.latency["baseline"]
    records = [r for r, _, _ in rec.glove]
    stamps = [s for _, s, _ in rec.glove]
    lost = sum(b - a - 1 for a, b in zip(records, records[1:]) if b > a + 1)
    rate = (len(stamps) - 1) / (stamps[-1] - stamps[0]) if len(stamps) > 1 else 0.0
    transit = serial_transit(rec.glove, glove_log) if os.path.exists(glove_log) else []

    with open(os.path.join(args.out, "latency.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["source", "latency_s"])
        for name, values in (("pipeline", pipeline), ("baseline", baseline), ("serial", transit)):
            for v in values:
                w.writerow([name, "%.9f" % v])

    print("teleop benchmark: %d joints, glove at %g Hz, %g s per phase" % (len(joints.name), args.rate, args.seconds))
    print("%-44s %8s %8s %8s %8s %7s" % ("", "p50 ms", "p90 ms", "p99 ms", "max ms", "n"))
    for name, values in (("glove -> physics step (teleop pipeline)", pipeline),
                         ("rospy command -> physics step (baseline)", baseline),
                         ("emulator write -> glove arrival (pty)", transit)):
        print("%-44s %8.3f %8.3f %8.3f %8.3f %7d" % (name, 1e3 * percentile(values, 0.5), 1e3 * percentile(values, 0.9),
                                                      1e3 * percentile(values, 0.99), 1e3 * max(values or [float("nan")]),
                                                      len(values)))
    print("%-44s %8.3f %8s %8.3f %8.3f %7s" % ("floor: wait for the next physics step", 1e3 * STEP / 2, "",
                                              1e3 * STEP * 0.99, 1e3 * STEP, ""))
    print("(the baseline is one ROS hop from a Python publisher plus the step wait: the whole C++ pipeline,"
          " two hops and the mapping, costs about as much)")
    print("glove records: %d at %.1f Hz sustained, %d lost" % (len(records), rate, lost))

    plot = os.path.join(os.path.dirname(os.path.abspath(__file__)), "plot_latency.py")
    subprocess.call(["/usr/bin/python3", plot, os.path.join(args.out, "latency.csv"), os.path.join(args.out, "latency.png")])
    bags = sorted(glob.glob(os.path.join(args.out, "demo_*.bag")))
    if bags:
        subprocess.call(["rosrun", "adroit_teleop", "demos", "plot", bags[-1], "--out",
                         os.path.join(args.out, "demonstration.png")])
        print("demonstration: %s" % bags[-1])
    print("plots: %s, %s" % (os.path.join(args.out, "latency.png"), os.path.join(args.out, "demonstration.png")))

    result("latency_p50", 1e3 * percentile(pipeline, 0.5), "ms", "<=", 5)
    result("latency_p99", 1e3 * percentile(pipeline, 0.99), "ms", "<=", 10)
    result("glove_rate", rate, "Hz", ">=", 100)
    result("glove_records_lost", lost, "records", "<=", 0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
