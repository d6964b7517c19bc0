#!/usr/bin/python3
"""Tests of scripts/demos on synthetic demonstration bags with known contents.

Standalone: `/usr/bin/python3 test_demos.py` (workspace sourced) runs every test that needs no
ROS master. LiveReplay needs a running simulation driver (adroit_driver adroit_sim, in a
teleop scene) and runs only with ADROIT_DEMOS_LIVE=1. As a rostest node (the --gtest_output
argument) the classes named in its arguments run (all when none is named: demos.test), and the
results go to rostest's XML file; demos_replay.test runs LiveReplay against a driver it starts.
"""
import importlib.machinery
import importlib.util
import math
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
import unittest

import rosbag
import rospy
from adroit_msgs.msg import ActuatorStates, GloveSensors, TendonForceCommand, ValveCommand
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, String

HERE = os.path.dirname(os.path.abspath(__file__))
# Installed next to this test (rostest), or in the source tree (run by hand).
SCRIPT = next(p for p in (os.path.join(HERE, "demos"), os.path.join(HERE, "..", "scripts", "demos")) if os.path.exists(p))
ATM = 101325.0
T0 = 1000.0  # ROS time of the synthetic bags' start
EPS = 1e-6   # s, as the tool's zero-order hold

METADATA = """task: 'pickup'
model: /nonexistent/mjcf/teleop_tube.xml
mode: force
calibration: /tmp/calibration.yaml
calibration_created: '2024-01-01'
calibration_note: 'synthetic'
sensors: 18
gains: {stiffness: 3000.0, damping: 30.0, min_tension: 0.3}
calibration_file: |
  created: '2024-01-01'
  sensors: 18
"""


def run(*args, timeout=120):
    """(exit status, stdout, stderr) of the tool run as a program."""
    proc = subprocess.run([sys.executable, SCRIPT] + [str(a) for a in args], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True, timeout=timeout)
    return proc.returncode, proc.stdout, proc.stderr


def load_tool():
    """The tool as a module (it has no .py suffix)."""
    loader = importlib.machinery.SourceFileLoader("demos_tool", SCRIPT)
    spec = importlib.util.spec_from_loader("demos_tool", loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


def stamp(s):
    return rospy.Time.from_sec(T0 + s)


def ticks(start, period, end):
    """Relative times start + k * period below end, as the generator and the checks use them."""
    out, k = [], 0
    while start + k * period < end:
        out.append(start + k * period)
        k += 1
    return out


def zoh(start, period, s):
    """Index of the newest sample of a start + k * period stream at or before s."""
    return int(math.floor((s - start) / period + EPS / period))


def parse_matrix_file(text):
    """Blocks of an adroit_learning MatrixFile, by matrix_file.cpp's rules (and stricter about
    numbers: plain decimal only). Raises ValueError."""
    tokens = []
    for line in text.splitlines():
        tokens += line.split("#", 1)[0].split()
    number = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")
    blocks, i = {}, 0
    while i < len(tokens):
        name = tokens[i]
        integer = re.compile(r"^[+-]?\d+$")  # strtol, whole token
        if i + 2 >= len(tokens) or not integer.match(tokens[i + 1]) or not integer.match(tokens[i + 2]):
            raise ValueError("block %s: bad header" % name)
        rows, cols = int(tokens[i + 1]), int(tokens[i + 2])
        if not (0 < rows <= 100000 and 0 < cols <= 100000):
            raise ValueError("block %s: bad shape" % name)
        if name in blocks:
            raise ValueError("block %s appears twice" % name)
        i += 3
        values = tokens[i:i + rows * cols]
        if len(values) < rows * cols:
            raise ValueError("block %s: file ends early" % name)
        for v in values:
            if not number.match(v) or not math.isfinite(float(v)):
                raise ValueError("block %s: bad number %r" % (name, v))
        blocks[name] = [[float(v) for v in values[r * cols:(r + 1) * cols]] for r in range(rows)]
        i += rows * cols
    return blocks


class Synthetic:
    """A demonstration with known signals; the knobs make the bad variants."""

    joints = ["WRJ1", "FFJ3", "FFJ2"]
    cylinders = ["A_c0", "A_c1", "A_c2", "A_c3"]
    js = (0.0003, 0.002)     # (first sample, period) [s after T0]: never on a sample time
    act = (0.0011, 0.004)
    odom = (0.0017, 0.004)
    cmd = (0.0105, 0.006)    # commands: the latest stream to start, so t0 = T0 + 0.0105
    glove = (0.0042, 0.01)
    command_delay = 0.007    # a command's header stamp (its glove record) precedes its recording
    quat_flip = 1.0          # s: from here on the odometry quaternion is negated (same rotation)

    def __init__(self, duration=2.0, metadata=METADATA, skip=(), actions=("force",), gap=None,
                 backwards=False, bad_sizes=False, press=None):
        self.duration, self.metadata, self.skip, self.actions = duration, metadata, set(skip), actions
        self.gap, self.backwards, self.bad_sizes = gap, backwards, bad_sizes
        self.press = press  # s: the dead-man is pressed then (None: pressed from the start)

    # The signals, at relative time s.
    def q(self, j, s):
        return 0.2 * (j + 1) * math.sin(2 * math.pi * (0.5 + 0.25 * j) * s) + 0.1 * j

    def qdot(self, j, s):
        f = 0.5 + 0.25 * j
        return 0.2 * (j + 1) * 2 * math.pi * f * math.cos(2 * math.pi * f * s)

    def pressure(self, c, s):
        return ATM + 1e5 * (c + 1) + 2000.0 * s

    def quaternion(self, s):
        # 120 deg about (1, 1, 1): maps x -> y, y -> z, z -> x.
        return (0.5, 0.5, 0.5, 0.5) if s < self.quat_flip else (-0.5, -0.5, -0.5, -0.5)

    def object_position(self, s):
        return (0.1, -0.2, 0.3 + 0.01 * s)

    body_velocity = (0.1, 0.2, 0.3)
    angular_velocity = (0.4, 0.5, 0.6)

    def command(self, k):
        """Command message k: even ones address every cylinder by name (in reverse order),
        odd ones only cylinder 2, by index."""
        if k % 2 == 0:
            return dict(name=list(reversed(self.cylinders)), values=[10.0 * c + 0.01 * k for c in (3, 2, 1, 0)])
        return dict(index=[2], values=[100.0 + k])

    def expected_command(self, k, c):
        """Cylinder c's value after command k."""
        if c == 2 and k % 2 == 1:
            return 100.0 + k
        even = k - (k % 2)
        return 10.0 * c + 0.01 * even

    def joint_state_times(self):
        times = ticks(self.js[0], self.js[1], self.duration)
        if self.gap:
            times = [s for s in times if not self.gap[0] < s < self.gap[1]]
        return times

    def write(self, path):
        with rosbag.Bag(path, "w") as bag:
            self._write(bag)

    def _write(self, bag):
        w = lambda topic, msg, s: None if topic in self.skip else bag.write(topic, msg, stamp(s))
        w("/adroit_teleop/metadata", String(data=self.metadata), 0.0)
        w("/adroit_teleop/enabled", Bool(data=self.press is None), 0.0)
        if self.press is not None:
            w("/adroit_teleop/enabled", Bool(data=True), self.press)
        js_times = self.joint_state_times()
        for i, s in enumerate(js_times):
            m = JointState(name=self.joints, position=[self.q(j, s) for j in range(3)],
                           velocity=[self.qdot(j, s) for j in range(3)], effort=[0.0] * 3)
            m.header.stamp = stamp(s)
            if self.backwards and i == len(js_times) // 2:
                m.header.stamp = stamp(s - 0.01)
            if self.bad_sizes and i == 10:
                m.position = m.position[:2]
            w("/adroit/joint_states", m, s)
        for s in ticks(self.act[0], self.act[1], self.duration):
            m = ActuatorStates(name=self.cylinders, pressure=[self.pressure(c, s) for c in range(4)],
                               length=[0.0] * 4, length_rate=[0.0] * 4, force=[1.0] * 4, command=[0.0] * 4,
                               supply_pressure=620000.0)
            m.header.stamp = stamp(s)
            w("/adroit/actuator_states", m, s)
        for s in ticks(self.odom[0], self.odom[1], self.duration):
            m = Odometry()
            m.header.stamp, m.header.frame_id, m.child_frame_id = stamp(s), "world", "object"
            p, q = m.pose.pose.position, m.pose.pose.orientation
            p.x, p.y, p.z = self.object_position(s)
            q.w, q.x, q.y, q.z = self.quaternion(s)
            v, a = m.twist.twist.linear, m.twist.twist.angular
            v.x, v.y, v.z = self.body_velocity
            a.x, a.y, a.z = self.angular_velocity
            w("/adroit/object/odom", m, s)
        for k, s in enumerate(ticks(self.cmd[0], self.cmd[1], self.duration - 0.005)):
            c = self.command(k)
            for kind in self.actions:
                if kind == "force":
                    m = TendonForceCommand(name=c.get("name", []), index=c.get("index", []), force=c["values"])
                    topic = "/adroit/tendon_force_command"
                else:  # valve commands: the same pattern, as volts / 10
                    m = ValveCommand(name=c.get("name", []), index=c.get("index", []),
                                     volts=[v / 10 for v in c["values"]])
                    topic = "/adroit/valve_command"
                m.header.stamp = stamp(s - self.command_delay)
                w(topic, m, s)
        for k, s in enumerate(ticks(self.glove[0], self.glove[1], self.duration)):
            g = GloveSensors(record=k, raw=bytes([1 + (k + i) % 255 for i in range(18)]))
            g.header.stamp = stamp(s)
            w("/adroit_teleop/glove", g, s)
            t = JointState(name=self.joints, position=[self.q(j, s) + 0.05 for j in range(3)])
            t.header.stamp = stamp(s)
            w("/adroit_teleop/joint_targets", t, s)


class DemosTestCase(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.mkdtemp(prefix="test_demos_")

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.dir, ignore_errors=True)

    def bag(self, name, demo=None):
        path = os.path.join(self.dir, name)
        (demo or Synthetic()).write(path)
        return path


class Validate(DemosTestCase):
    def check_invalid(self, path, *reasons):
        code, out, err = run("validate", path)
        self.assertEqual(code, 1, out + err)
        self.assertTrue(out.startswith(path + ": invalid: "), out)
        for reason in reasons:
            self.assertIn(reason, out)

    def test_good_bag_is_ok(self):
        path = self.bag("good.bag")
        code, out, err = run("validate", path)
        self.assertEqual(code, 0, out + err)
        self.assertEqual(len(out.splitlines()), 1)
        self.assertTrue(out.startswith(path + ": ok ("), out)
        self.assertIn("task pickup", out)
        self.assertIn("mode force", out)

    def test_truncated_bag(self):
        good = self.bag("to_cut.bag")
        path = os.path.join(self.dir, "truncated.bag")
        with open(good, "rb") as f:
            data = f.read()
        with open(path, "wb") as f:
            f.write(data[:len(data) // 2])
        self.check_invalid(path, "cannot open", "unindexed")

    def test_not_a_bag(self):
        path = os.path.join(self.dir, "notes.bag")
        with open(path, "w") as f:
            f.write("these are not the messages you are looking for\n" * 20)
        self.check_invalid(path, "not a rosbag file (it starts with b'these are not th'")

    def test_missing_file(self):
        self.check_invalid(os.path.join(self.dir, "absent.bag"), "no such file")

    def test_missing_topic(self):
        path = self.bag("no_glove.bag", Synthetic(skip=["/adroit_teleop/glove"]))
        self.check_invalid(path, "missing required topics: /adroit_teleop/glove")

    def test_no_commands(self):
        path = self.bag("no_commands.bag", Synthetic(actions=()))
        self.check_invalid(path, "no commands")

    def test_gap_in_joint_states(self):
        path = self.bag("gap.bag", Synthetic(gap=(1.0, 1.2)))
        self.check_invalid(path, "joint_states gap of 0.20")

    def test_stamps_going_backwards(self):
        path = self.bag("backwards.bag", Synthetic(backwards=True))
        self.check_invalid(path, "joint_states stamps go backwards")

    def test_sizes_disagree_with_names(self):
        path = self.bag("sizes.bag", Synthetic(bad_sizes=True))
        self.check_invalid(path, "joint_states sizes disagree with their names", "message 10")

    def test_metadata_without_task(self):
        meta = "\n".join(l for l in METADATA.splitlines() if not l.startswith("task:"))
        path = self.bag("no_task.bag", Synthetic(metadata=meta))
        self.check_invalid(path, "metadata has no task")

    def test_metadata_not_yaml(self):
        path = self.bag("bad_yaml.bag", Synthetic(metadata="task: [pickup\nmode: force\n"))
        self.check_invalid(path, "metadata is not YAML")

    def test_too_short(self):
        path = self.bag("short.bag", Synthetic(duration=0.3))
        self.check_invalid(path, "too short")

    def test_bad_bag_does_not_stop_the_good_ones(self):
        good1 = self.bag("good1.bag")
        bad = os.path.join(self.dir, "bad.bag")
        with open(bad, "w") as f:
            f.write("junk")
        good2 = self.bag("good2.bag", Synthetic(actions=("valve",)))
        code, out, err = run("validate", good1, bad, good2)
        self.assertEqual(code, 1, out + err)
        lines = out.splitlines()
        self.assertEqual(len(lines), 3, out)
        self.assertTrue(lines[0].startswith(good1 + ": ok"), lines[0])
        self.assertTrue(lines[1].startswith(bad + ": invalid: not a rosbag file"), lines[1])
        self.assertTrue(lines[2].startswith(good2 + ": ok"), lines[2])


class List(DemosTestCase):
    def test_list_directory(self):
        folder = os.path.join(self.dir, "listing")
        os.mkdir(folder)
        Synthetic().write(os.path.join(folder, "a_good.bag"))
        Synthetic(skip=["/adroit_teleop/joint_targets"]).write(os.path.join(folder, "b_bad.bag"))
        code, out, err = run("list", folder)
        self.assertEqual(code, 1, out + err)
        lines = out.splitlines()
        self.assertEqual(len(lines), 2, out)
        self.assertTrue(lines[0].startswith("a_good.bag"), lines[0])
        self.assertIn("task=pickup", lines[0])
        self.assertIn("mode=force", lines[0])
        self.assertIn("joints=1000", lines[0])
        self.assertIn("actuators=500", lines[0])
        self.assertIn("odom=500", lines[0])
        self.assertTrue(lines[0].endswith("ok"), lines[0])
        self.assertIn("2.0 s", lines[0])
        self.assertIn("t=1000.000 s (sim)", lines[0])  # ROS time 1000 s: simulated time
        self.assertIn("invalid: missing required topics: /adroit_teleop/joint_targets", lines[1])

    def test_list_good_bags_only(self):
        path = self.bag("only.bag")
        code, out, err = run("list", path)
        self.assertEqual(code, 0, out + err)
        self.assertEqual(len(out.splitlines()), 1)


class Export(DemosTestCase):
    @classmethod
    def setUpClass(cls):
        super().setUpClass()
        cls.demo = Synthetic()
        cls.path = os.path.join(cls.dir, "export.bag")
        cls.demo.write(cls.path)
        cls.out = os.path.join(cls.dir, "export.txt")
        code, out, err = run("export", cls.path, "--out", cls.out)
        assert code == 0, out + err
        with open(cls.out) as f:
            cls.text = f.read()
        cls.blocks = parse_matrix_file(cls.text)

    def sample_time(self, k, dt=0.04):
        return self.demo.cmd[0] + k * dt  # relative to T0; t0 is the first command

    def test_blocks_and_shapes(self):
        b = self.blocks
        self.assertEqual(list(b), ["X", "U", "t", "dt"])
        # js last at 1.9983 s, t0 = 0.0105 s: floor(1.9878 / 0.04) + 1 samples.
        T = 50
        self.assertEqual((len(b["X"]), len(b["X"][0])), (T, 2 * 3 + 12 + 4))
        self.assertEqual((len(b["U"]), len(b["U"][0])), (T, 4))
        self.assertEqual((len(b["t"]), len(b["t"][0])), (T, 1))
        self.assertEqual(b["dt"], [[0.04]])
        for k in (0, 1, 17, 49):
            self.assertAlmostEqual(b["t"][k][0], k * 0.04, delta=1e-9)

    def test_export_starts_at_the_dead_man_press(self):
        # Pressed 0.5 s in: the demonstration is what happened from then on, not the idle hand.
        demo = Synthetic(press=0.5)
        path = os.path.join(self.dir, "pressed_late.bag")
        demo.write(path)
        out = os.path.join(self.dir, "pressed_late.txt")
        code, stdout, err = run("export", path, "--out", out)
        self.assertEqual(code, 0, stdout + err)
        with open(out) as f:
            text = f.read()
        blocks = parse_matrix_file(text)
        # js last at 1.9983 s, t0 = the press at 0.5 s: floor(1.4983 / 0.04) + 1 samples.
        self.assertEqual(len(blocks["X"]), 38)
        self.assertAlmostEqual(blocks["X"][0][0], demo.q(0, 0.4983), delta=1e-12)  # newest at or before 0.5 s
        self.assertIn("from %.9f" % (T0 + 0.5), text)

    def test_comments_describe_the_layout(self):
        header = [l for l in self.text.splitlines() if l.startswith("#")]
        joined = "\n".join(header)
        self.assertIn("WRJ1 FFJ3 FFJ2", joined)
        self.assertIn("A_c0 A_c1 A_c2 A_c3", joined)
        self.assertIn("object: yes", joined)
        self.assertIn("actions: force", joined)
        self.assertIn(os.path.abspath(self.path), joined)
        self.assertIn("task: pickup", joined)
        self.assertIn("mode: force", joined)
        self.assertIn("q:3 object_position:3 object_rotation_vector:3 qdot:3 object_linear_velocity_world:3 "
                      "object_angular_velocity_body:3 pressure_bar_gauge:4", joined)
        first_block = next(i for i, l in enumerate(self.text.splitlines()) if not l.startswith("#"))
        self.assertEqual(first_block, len(header))  # comments at the top

    def test_state_values_zero_order_hold(self):
        d = self.demo
        for k in (0, 1, 7, 24, 30, 49):
            s = self.sample_time(k)
            x = self.blocks["X"][k]
            sj = d.js[0] + zoh(d.js[0], d.js[1], s) * d.js[1]
            for j in range(3):
                self.assertAlmostEqual(x[j], d.q(j, sj), delta=1e-12, msg="q%d at sample %d" % (j, k))
                self.assertAlmostEqual(x[9 + j], d.qdot(j, sj), delta=1e-12, msg="qdot%d at sample %d" % (j, k))
            so = d.odom[0] + zoh(d.odom[0], d.odom[1], s) * d.odom[1]
            for i in range(3):
                self.assertAlmostEqual(x[3 + i], d.object_position(so)[i], delta=1e-12)
            sa = d.act[0] + zoh(d.act[0], d.act[1], s) * d.act[1]
            for c in range(4):
                # (p - 101325) / 1e5 = c + 1 + 0.02 sa
                self.assertAlmostEqual(x[18 + c], c + 1 + 0.02 * sa, delta=1e-9, msg="pressure %d" % c)

    def test_object_rotation_vector_and_velocities(self):
        angle = 2 * math.pi / 3 / math.sqrt(3)  # 120 deg about (1, 1, 1) / sqrt(3)
        for k in (3, 24, 30, 45):  # both signs of the recorded quaternion (flip at 1 s)
            x = self.blocks["X"][k]
            for i in range(3):
                self.assertAlmostEqual(x[6 + i], angle, delta=1e-12, msg="rotation vector at sample %d" % k)
            # Body velocity (0.1, 0.2, 0.3) under x -> y, y -> z, z -> x is (0.3, 0.1, 0.2) in the world.
            for i, v in enumerate((0.3, 0.1, 0.2)):
                self.assertAlmostEqual(x[12 + i], v, delta=1e-12, msg="world linear velocity at sample %d" % k)
            for i, v in enumerate((0.4, 0.5, 0.6)):
                self.assertAlmostEqual(x[15 + i], v, delta=1e-12, msg="body angular velocity at sample %d" % k)

    def test_commands_by_name_and_index(self):
        d = self.demo
        odd_seen = even_seen = False
        for k in range(50):
            s = self.sample_time(k)
            # Commands are held from when they were recorded, not from their (earlier) stamps.
            n = zoh(d.cmd[0], d.cmd[1], s)
            u = self.blocks["U"][k]
            for c in range(4):
                self.assertAlmostEqual(u[c], d.expected_command(n, c), delta=1e-12,
                                       msg="cylinder %d at sample %d (command %d)" % (c, k, n))
            odd_seen |= n % 2 == 1
            even_seen |= n % 2 == 0
        self.assertTrue(odd_seen and even_seen)  # both addressings were the newest somewhere
        # Column 2 took the index-addressed value; the others kept the named ones.
        k = 2
        n = zoh(d.cmd[0], d.cmd[1], self.sample_time(k))
        self.assertEqual(n % 2, 1)
        self.assertEqual(self.blocks["U"][k][2], 100.0 + n)
        self.assertEqual(self.blocks["U"][k][3], 30.0 + 0.01 * (n - 1))

    def test_mean_commands_average_each_step(self):
        # --commands mean: U is the mean of the held command over [t_k, t_k + dt), worked out
        # here from the commands' recorded times (each held until the next one).
        d = self.demo
        out = os.path.join(self.dir, "export_mean.txt")
        code, stdout, err = run("export", self.path, "--out", out, "--commands", "mean")
        self.assertEqual(code, 0, stdout + err)
        with open(out) as f:
            text = f.read()
        self.assertIn("the mean command over each step", text)
        U = parse_matrix_file(text)["U"]
        with rosbag.Bag(self.path) as bag:  # the recorded times as the bag keeps them (whole ns)
            times = [t.to_sec() - T0 for _, _, t in bag.read_messages(topics=["/adroit/tendon_force_command"])]

        def held_mean(c, a, b):
            total = 0.0
            for n, t in enumerate(times):
                end = times[n + 1] if n + 1 < len(times) else b
                total += max(0.0, min(b, end) - max(a, t)) * d.expected_command(n, c)
            return total / (b - a)

        for k in (0, 1, 7, 30):
            start = times[0] + k * 0.04  # t0: the first command, the latest stream to start
            for c in (0, 2):
                self.assertAlmostEqual(U[k][c], held_mean(c, start, start + 0.04), delta=1e-9,
                                       msg="cylinder %d, step %d" % (c, k))
        # A held command differs from the step's mean where a command changed inside the step.
        self.assertNotAlmostEqual(U[1][2], self.blocks["U"][1][2], delta=1e-3)

    def test_numbers_round_trip_exactly(self):
        d = self.demo
        s = self.sample_time(7)
        sj = d.js[0] + zoh(d.js[0], d.js[1], s) * d.js[1]
        self.assertEqual(self.blocks["X"][7][0], d.q(0, sj))  # full precision, no rounding

    def test_valve_actions_and_no_object(self):
        path = self.bag("valve_only.bag", Synthetic(actions=("force", "valve"), skip=["/adroit/object/odom"]))
        out = os.path.join(self.dir, "valve.txt")
        code, stdout, err = run("export", path, "--out", out, "--dt", "0.1")
        self.assertEqual(code, 0, stdout + err)
        self.assertIn("(valve)", stdout)  # both kinds: auto takes the valves
        with open(out) as f:
            text = f.read()
        b = parse_matrix_file(text)
        self.assertIn("# object: no", text)
        self.assertIn("actions: valve", text)
        self.assertEqual(len(b["X"][0]), 2 * 3 + 4)
        self.assertEqual(len(b["U"][0]), 4)
        self.assertEqual(b["dt"], [[0.1]])
        d = Synthetic()
        n = zoh(d.cmd[0], d.cmd[1], d.cmd[0] + 0.1 * 3)
        self.assertAlmostEqual(b["U"][3][2], d.expected_command(n, 2) / 10, delta=1e-12)
        # Without an object the pressures follow qdot directly.
        sa = d.act[0] + zoh(d.act[0], d.act[1], d.cmd[0]) * d.act[1]
        self.assertAlmostEqual(b["X"][0][6], 1 + 0.02 * sa, delta=1e-9)
        # Forced to the tendon forces instead.
        code, stdout, err = run("export", path, "--out", out, "--actions", "force")
        self.assertEqual(code, 0, stdout + err)
        with open(out) as f:
            self.assertIn("actions: force", f.read())

    def test_missing_action_kind_fails_naming_the_bag(self):
        out = os.path.join(self.dir, "none.txt")
        code, stdout, err = run("export", self.path, "--out", out, "--actions", "valve")
        self.assertEqual(code, 1)
        self.assertIn(self.path, err)
        self.assertIn("no valve commands", err)
        self.assertFalse(os.path.exists(out))

    def test_invalid_bag_is_not_exported(self):
        path = self.bag("export_gap.bag", Synthetic(gap=(0.5, 0.9)))
        code, stdout, err = run("export", path, "--out", os.path.join(self.dir, "gap.txt"))
        self.assertEqual(code, 1)
        self.assertIn(path, err)
        self.assertIn("gap", err)

    def test_usage_errors(self):
        self.assertEqual(run("export", self.path)[0], 2)  # no --out
        self.assertEqual(run("export", self.path, "--out", "x", "--dt", "-1")[0], 2)
        self.assertEqual(run("export", self.path, "--out", "x", "--actions", "torque")[0], 2)
        self.assertEqual(run()[0], 2)
        self.assertEqual(run("frobnicate")[0], 2)
        self.assertEqual(run("replay", self.path, "--every", "0")[0], 2)


class Plot(DemosTestCase):
    def test_plot_writes_a_png(self):
        path = self.bag("plot.bag")
        png = os.path.join(self.dir, "plot.png")
        code, out, err = run("plot", path, "--out", png)
        self.assertEqual(code, 0, out + err)
        with open(png, "rb") as f:
            self.assertEqual(f.read(8), b"\x89PNG\r\n\x1a\n")
        self.assertIn("FFJ2", out)

    def test_plot_of_a_broken_bag_fails_naming_it(self):
        path = os.path.join(self.dir, "broken_plot.bag")
        with open(path, "w") as f:
            f.write("x")
        code, out, err = run("plot", path, "--out", os.path.join(self.dir, "broken.png"))
        self.assertEqual(code, 1)
        self.assertIn(path, err)


class OutsideFiles(DemosTestCase):
    """Whatever a path names, every command answers with one line naming it: no traceback, no
    blocking on a FIFO, no endless read of a device, no bag read past the size limit."""

    COMMANDS = (("validate",), ("list",), ("export", "--out", "{dir}/out.txt"), ("plot", "--out", "{dir}/out.png"),
                ("replay",))

    def check_refused(self, path, reason, commands=COMMANDS):
        """Every command refuses `path` within 20 s with one line naming it and `reason`."""
        for command in commands:
            extra = [a.format(dir=self.dir) for a in command[1:]]
            code, out, err = run(command[0], path, *extra, timeout=20)
            line = (out + err).strip()
            self.assertEqual(code, 1, "%s: %s" % (command[0], line))
            self.assertEqual(len(line.splitlines()), 1, "%s: %s" % (command[0], line))
            self.assertNotIn("Traceback", line)
            name = os.path.basename(path) if command[0] == "list" else path
            self.assertTrue(line.startswith(name), "%s: %s" % (command[0], line))
            self.assertIn(reason, line, command[0])
        self.assertFalse(os.path.exists(os.path.join(self.dir, "out.txt")))

    def write(self, name, data):
        path = os.path.join(self.dir, name)
        with open(path, "wb") as f:
            f.write(data)
        return path

    def test_random_bytes_are_not_a_bag(self):
        data = bytes(random.Random(7).getrandbits(8) for _ in range(4096))
        self.check_refused(self.write("random.bag", data), "not a rosbag file (it starts with b'")

    def test_text_is_not_a_bag(self):
        path = self.write("text.bag", "h\u00e9llo, not a bag\n".encode("utf-8") * 50)
        self.check_refused(path, "not a rosbag file (it starts with b'h\\xc3\\xa9llo, not a ba', not '#ROSBAG V2.0')")

    def test_empty_file_is_not_a_bag(self):
        self.check_refused(self.write("empty.bag", b""), "not a rosbag file (empty file)")

    def test_bag_version_line_that_is_not_text(self):
        self.check_refused(self.write("header.bag", b"#ROSBAG V\xff\xfe\n" + bytes(100)), "not a rosbag file")

    def test_fifo_is_refused_without_blocking(self):
        path = os.path.join(self.dir, "pipe.bag")
        os.mkfifo(path)
        self.check_refused(path, "not a regular file (a FIFO)")

    def test_device_is_refused_without_reading_it(self):
        self.check_refused("/dev/zero", "not a regular file (a character device)")

    def test_directory_is_refused(self):
        path = os.path.join(self.dir, "folder.bag")
        os.mkdir(path)
        # (list lists the bags in a directory)
        self.check_refused(path, "not a regular file (a directory)", [c for c in self.COMMANDS if c[0] != "list"])

    def test_bag_over_the_default_limit_is_refused_unread(self):
        # A rosbag's first line, then 4 GiB of nothing (sparse: no disk used).
        path = self.write("huge.bag", b"#ROSBAG V2.0\n")
        os.truncate(path, 4 * 1024 ** 3 + 1)
        try:
            self.check_refused(path, "4 GiB (4294967297 bytes), over the limit of 4 GiB (4294967296 bytes; --max-size)")
        finally:
            os.unlink(path)

    def test_max_size_sets_the_limit(self):
        path = self.bag("limit.bag")
        size = os.path.getsize(path)
        code, out, err = run("validate", path, "--max-size", str(size - 1))
        self.assertEqual(code, 1, out + err)
        self.assertEqual(out, "%s: invalid: %.3g KiB (%d bytes), over the limit of %.3g KiB (%d bytes; --max-size)\n"
                         % (path, size / 1024, size, (size - 1) / 1024, size - 1))
        code, out, err = run("validate", path, "--max-size", str(size))  # at the limit: read
        self.assertEqual(code, 0, out + err)
        code, out, err = run("validate", path, "--max-size", "1M")
        self.assertEqual(code, 0, out + err)
        for bad in ("0", "-5", "lots", "1.5X"):
            code, out, err = run("validate", path, "--max-size", bad)
            self.assertEqual(code, 2, bad)
            self.assertIn("not a size", err)


class ExportOutput(DemosTestCase):
    """export writes a whole file or nothing, and never leaves its temporary file behind."""

    @classmethod
    def setUpClass(cls):
        super().setUpClass()
        cls.source = os.path.join(cls.dir, "trial.bag")
        Synthetic().write(cls.source)

    def setUp(self):
        self.out = tempfile.mkdtemp(dir=self.dir)

    def listing(self):
        return sorted(os.listdir(self.out))

    def test_out_directory_writes_the_bags_name_into_it(self):
        code, out, err = run("export", self.source, "--out", self.out)
        self.assertEqual(code, 0, out + err)
        self.assertEqual(self.listing(), ["trial.txt"])
        self.assertFalse(os.path.exists(self.out + ".tmp"))
        self.assertIn("wrote %s" % os.path.join(self.out, "trial.txt"), out)
        with open(os.path.join(self.out, "trial.txt")) as f:
            self.assertEqual(len(parse_matrix_file(f.read())["X"]), 50)

    def test_success_replaces_the_file_and_leaves_nothing_else(self):
        target = os.path.join(self.out, "demo.txt")
        with open(target, "w") as f:
            f.write("old")
        code, out, err = run("export", self.source, "--out", target)
        self.assertEqual(code, 0, out + err)
        self.assertEqual(self.listing(), ["demo.txt"])
        with open(target) as f:
            self.assertIn("X 50 22", f.read())

    def test_failures_leave_nothing_behind(self):
        os.mkdir(os.path.join(self.out, "trial.txt"))  # where --out DIR would write: a directory
        os.mkfifo(os.path.join(self.out, "pipe.txt"))
        bad = self.bag("export_short.bag", Synthetic(duration=0.3))
        cases = [((self.source, "--out", self.out), "exists and is a directory: not replaced"),
                 ((self.source, "--out", os.path.join(self.out, "pipe.txt")), "exists and is not a regular file"),
                 ((self.source, "--out", os.path.join(self.out, "no", "x.txt")), "no directory"),
                 ((bad, "--out", os.path.join(self.out, "short.txt")), "too short"),
                 ((self.source, "--out", os.path.join(self.out, "v.txt"), "--actions", "valve"), "no valve commands")]
        for args, reason in cases:
            code, out, err = run("export", *args)
            self.assertEqual(code, 1, out + err)
            self.assertEqual(len(err.splitlines()), 1, err)
            self.assertIn(reason, err)
            self.assertEqual(self.listing(), ["pipe.txt", "trial.txt"], args)
        self.assertFalse(os.path.exists(self.out + ".tmp"))

    def test_write_errors_and_interrupts_remove_the_temporary_file(self):
        import contextlib
        import errno
        import io
        from unittest import mock
        tool = load_tool()
        target = os.path.join(self.out, "x.txt")
        cases = ((OSError(errno.ENOSPC, "No space left on device"), 1,
                  "%s: export failed: cannot write %s: No space left on device\n" % (self.source, target)),
                 (KeyboardInterrupt(), 130, "demos: interrupted\n"))
        for failure, status, message in cases:
            err = io.StringIO()
            with mock.patch.object(tool.os, "replace", side_effect=failure), contextlib.redirect_stderr(err):
                self.assertEqual(tool.main(["export", self.source, "--out", target]), status)
            self.assertEqual(err.getvalue(), message)
            self.assertEqual(self.listing(), [])


class ModelLayout(unittest.TestCase):
    """The replay's generalised-coordinate order, read from the MJCF (no driver needed)."""

    def test_joints_in_document_order_with_their_sizes(self):
        xml = """<mujoco><default><joint type="slide"/></default>
          <worldbody><body name="base"><freejoint name="hand_base"/>
            <body><joint name="a" axis="1 0 0"/><body><joint name="b" type="ball"/></body></body>
            <body><joint name="c" type="slide"/></body></body>
            <body name="object"><joint name="object_root" type="free"/></body></worldbody>
          <tendon><fixed name="t"><joint joint="a" coef="1"/></fixed></tendon>
          <keyframe><key name="rest" qpos="9"/>
            <key name="home" qpos="1 2 3 1 0 0 0 0.5 1 0 0 0 0.25 0 0 0 1 0 0 0"/></keyframe>
        </mujoco>"""
        with tempfile.NamedTemporaryFile("w", suffix=".xml", delete=False) as f:
            f.write(xml)
        try:
            layout, home = load_tool().read_model(f.name)
        finally:
            os.unlink(f.name)
        self.assertEqual(layout, [("hand_base", "free", 7, 6), ("a", "hinge", 1, 1), ("b", "ball", 4, 3),
                                  ("c", "slide", 1, 1), ("object_root", "free", 7, 6)])
        self.assertEqual(len(home), 20)
        self.assertEqual(home[:7], [1, 2, 3, 1, 0, 0, 0])


@unittest.skipUnless(os.environ.get("ADROIT_DEMOS_LIVE") == "1", "needs a running adroit_sim (ADROIT_DEMOS_LIVE=1)")
class LiveReplay(unittest.TestCase):
    """demos replay against the running driver (demos_replay.test starts adroit_sim in the
    teleop_tube scene with sensor realism, as sim.yaml has it)."""

    @classmethod
    def setUpClass(cls):
        import rospkg
        rospy.init_node("test_demos_live", anonymous=True, disable_signals=True)
        cls.driver = os.environ.get("ADROIT_DEMOS_DRIVER", "/adroit_sim")
        cls.scene = rospy.get_param(cls.driver + "/scene", "teleop_tube")
        cls.mjcf = os.path.join(rospkg.RosPack().get_path("adroit_description"), "mjcf")
        cls.model = rospy.get_param(cls.driver + "/model_file", "") or os.path.join(cls.mjcf, cls.scene + ".xml")
        cls.mode = rospy.get_param(cls.driver + "/mode", "pneumatic")

    def setUp(self):
        # Each test starts from a running driver (a replay leaves it paused).
        from std_srvs.srv import SetBool
        rospy.wait_for_service("/adroit/pause", timeout=60)
        self.assertTrue(rospy.ServiceProxy("/adroit/pause", SetBool)(False).success)
        rospy.wait_for_message("/adroit/joint_states", JointState, timeout=30)
        self.folder = tempfile.mkdtemp(prefix="test_demos_live_")

    def tearDown(self):
        shutil.rmtree(self.folder, ignore_errors=True)

    def publishing(self, seconds=0.5):
        """How many joint_states the driver publishes in `seconds`."""
        counted = []
        sub = rospy.Subscriber("/adroit/joint_states", JointState, counted.append)
        time.sleep(seconds)
        sub.unregister()
        return len(counted)

    def write_live_bag(self, path, model):
        """A 1 s bag of states the driver accepts: its joints, inside the model's joint ranges,
        its cylinders and object; the metadata names `model` as the scene's."""
        import xml.etree.ElementTree as ET
        from adroit_msgs.msg import ActuatorStates as Actuators
        joints = rospy.wait_for_message("/adroit/joint_states", JointState, timeout=30)
        actuators = rospy.wait_for_message("/adroit/actuator_states", Actuators, timeout=30)
        try:
            odom = rospy.wait_for_message("/adroit/object/odom", Odometry, timeout=2)
        except rospy.ROSException:
            odom = None
        ranges = {}
        for el in ET.parse(self.model).getroot().find("worldbody").iter("joint"):
            if el.get("range"):
                ranges[el.get("name")] = [float(v) for v in el.get("range").split()]
        names, now = list(joints.name), dict(zip(joints.name, joints.position))

        class Live(Synthetic):
            def q(self, j, s):
                name = names[j]
                if name not in ranges:
                    return now[name]
                lo, hi = ranges[name]
                return (lo + hi) / 2 + 0.2 * (hi - lo) / 2 * math.sin(2 * math.pi * 0.5 * s + j)

            def qdot(self, j, s):
                if names[j] not in ranges:
                    return 0.0
                lo, hi = ranges[names[j]]
                return 0.2 * (hi - lo) / 2 * math.pi * math.cos(2 * math.pi * 0.5 * s + j)

            def _write(self, bag):
                super()._write(bag)
                for s in ticks(self.js[0], self.js[1], self.duration):
                    m = JointState(name=names, position=[self.q(j, s) for j in range(len(names))],
                                   velocity=[self.qdot(j, s) for j in range(len(names))])
                    m.header.stamp = stamp(s)
                    bag.write("/adroit/joint_states", m, stamp(s))
                for s in ticks(self.act[0], self.act[1], self.duration):
                    pressure = [ATM + 30000 + 1000 * c for c in range(len(actuators.name))]
                    m = ActuatorStates(name=actuators.name, pressure=pressure)
                    m.header.stamp = stamp(s)
                    bag.write("/adroit/actuator_states", m, stamp(s))
                if odom is not None:
                    for s in ticks(self.odom[0], self.odom[1], self.duration):
                        odom.header.stamp = stamp(s)
                        bag.write("/adroit/object/odom", odom, stamp(s))

        metadata = METADATA.replace("/nonexistent/mjcf/teleop_tube.xml", model)
        metadata = metadata.replace("mode: force", "mode: " + self.mode)
        skip = ["/adroit/joint_states", "/adroit/actuator_states", "/adroit/object/odom"]  # written by Live
        actions = ("force",) if self.mode == "force" else ("valve",)
        Live(duration=1.0, metadata=metadata, skip=skip, actions=actions).write(path)
        return path

    def test_bag_of_another_scene_is_refused_naming_both_scenes(self):
        # teleop_ball and teleop_tube have the same joints and coordinates: only the object
        # differs, so nothing but the scene check stops such a replay.
        other = "teleop_ball" if self.scene != "teleop_ball" else "teleop_tube"
        path = os.path.join(self.folder, "other_scene.bag")
        self.write_live_bag(path, os.path.join(self.mjcf, other + ".xml"))
        code, out, err = run("replay", path, "--every", "50", "--timeout", "20")
        self.assertEqual(code, 1, out + err)
        self.assertEqual(out, "")
        self.assertEqual(err, "%s: replay failed: the bag was recorded in scene %s, but the driver %s runs scene %s "
                         "(start the driver with scene %s)\n" % (path, other, self.driver, self.scene, other))
        self.assertGreater(self.publishing(), 0)  # refused before anything was done to the driver

    def test_clean_replay_into_its_own_scene_passes_the_default_tolerance(self):
        path = self.write_live_bag(os.path.join(self.folder, "live.bag"), self.model)
        # Every 5th of 500 samples: 100 states x every joint, thousands of noisy readings, so
        # that the sensor noise shows (the old 0.01 rad default failed on such a clean replay).
        code, out, err = run("replay", path, "--every", "5", "--timeout", "20")
        self.assertEqual(code, 0, out + err)
        self.assertIn("replayed 100 of 500", out)
        self.assertIn("left paused", out)
        error = float(re.search(r"joint error max ([0-9.]+) rad", out).group(1))
        # Within 8 sigma (+ half a step) of the noise the driver says it adds.
        sensors = rospy.get_param(self.driver + "/sensors", {})
        bound = 8 * sensors.get("joint_noise_std", 0.0) + sensors.get("joint_quantum", 0.0) / 2
        self.assertLess(error, max(bound, 1e-9))
        self.assertEqual(self.publishing(), 0)  # paused: nothing more comes out of the driver


if __name__ == "__main__":
    if any(a.startswith("--gtest_output") for a in sys.argv):
        # As a rostest node: every class, results in rostest's XML file.
        import rosunit
        result_file = next(a.split("=", 1)[1].split(":", 1)[1] for a in sys.argv if a.startswith("--gtest_output"))
        # The tests from this file's globals: run through catkin's relay script, this code is
        # exec'd in a namespace of its own and sys.modules["__main__"] (the relay) holds none.
        import types
        module = types.ModuleType("test_demos")
        module.__dict__.update(globals())
        named = [a for a in sys.argv[1:] if not a.startswith("-") and ":=" not in a]
        loader = unittest.TestLoader()
        suite = loader.loadTestsFromNames(named, module) if named else loader.loadTestsFromModule(module)
        result = rosunit.create_xml_runner("adroit_teleop", "_".join(["test_demos"] + named), result_file).run(suite)
        rosunit.print_unittest_summary(result)
        sys.exit(0 if result.wasSuccessful() else 1)
    unittest.main()
