#!/usr/bin/python3
"""Integration test of pool_node (or the pool nodelet), one pool or a group, against a real
roscore.

The test node plays the driver: it publishes /adroit/actuator_states at 200 Hz from a
first-order pressure response to the valve commands the pool sends (so the loop closes)
and force references as the behaviour MPC would. It checks that the pool commands exactly
its cylinders at its rate (~rate: one message per tick) with finite values in [-5, 5], by
index into the actuator-state order, tracks the reference, rejects bad references (NaN,
wrong length, unknown name, stamps far from the clock) and stale actuator states, each
counted by reason in /adroit/diagnostics, counts negative forces it clamps, keeps commanding
from the last valid plan, exhausts after the reference timeout, and that a bad configuration
stops the node with one line naming the field. For a group (~members: [status name,
cylinders] per pool) ~pool is every cylinder of the group: one command per tick carries them
all, when the states stop every cylinder of every pool exhausts, and each pool reports its
own status.
"""
import math
import os
import subprocess
import tempfile
import threading
import time
import unittest

import rospy
import rostest
from adroit_msgs.msg import ActuatorStates, ForceReference, ValveCommand
from diagnostic_msgs.msg import DiagnosticArray

ATM = 101325.0
SUPPLY = 620e3
EXHAUST = -5.0
RATE = 200.0


class FirstOrderPlant:
    """Chamber pressure relaxing to a command-dependent level (the shape of thesis eq. 5.7:
    sigmoid steady state between room and supply, rate growing with |u|)."""

    def __init__(self, n):
        self.p = [ATM] * n
        self.u = [EXHAUST] * n

    def step(self, dt):
        cb, cs = (SUPPLY + ATM) / 2, (SUPPLY - ATM) / 2
        for i, u in enumerate(self.u):
            z = 2.0 * u + 0.5 * u ** 3
            target = cb + cs * z / math.sqrt(1 + z * z)
            rate = 20.0 + 80.0 * abs(u)
            self.p[i] = target + (self.p[i] - target) * math.exp(-rate * dt)


class PoolTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.pool = rospy.get_param("~pool")
        cls.bores = [math.pi * d * d / 4 for d in rospy.get_param("~bore_diameter")]
        cls.timeout = rospy.get_param("~reference_timeout")
        cls.tick_phase = rospy.get_param("~tick_phase", 0.0)
        cls.rate = rospy.get_param("~rate", RATE)  # the pool's valve commands (the states stay at RATE)
        cls.members = rospy.get_param("~members", [])  # a group: [status name, its cylinders] per pool
        cls.states_paused = False  # the driver falls silent (a stale state)
        # Cylinders of other pools: their states (NaN!) and references must not disturb this pool.
        cls.others = ["A_MFJ2_flex", "A_THJ1_ext"]
        cls.state_names = cls.pool + cls.others  # the order valve command indices refer to
        cls.lock = threading.Lock()
        cls.plant = FirstOrderPlant(len(cls.pool))
        cls.commands = []  # (receipt time, msg)
        cls.diagnostics = []
        cls.state_pub = rospy.Publisher("/adroit/actuator_states", ActuatorStates, queue_size=10, tcp_nodelay=True)
        cls.ref_pub = rospy.Publisher("/adroit/force_reference", ForceReference, queue_size=10)
        rospy.Subscriber("/adroit/valve_command", ValveCommand, cls.on_command, tcp_nodelay=True)
        rospy.Subscriber("/adroit/diagnostics", DiagnosticArray, cls.on_diagnostics)
        cls.running = True
        cls.thread = threading.Thread(target=cls.driver_loop, daemon=True)
        cls.thread.start()

    @classmethod
    def tearDownClass(cls):
        cls.running = False
        cls.thread.join(2.0)

    @classmethod
    def on_command(cls, msg):
        with cls.lock:
            cls.commands.append((time.monotonic(), msg))
            names = [cls.state_names[i] for i in msg.index] if msg.index else msg.name
            for name, v in zip(names, msg.volts):
                if name in cls.pool and math.isfinite(v):
                    cls.plant.u[cls.pool.index(name)] = max(-5.0, min(5.0, v))

    @classmethod
    def on_diagnostics(cls, msg):
        with cls.lock:
            cls.diagnostics.extend(msg.status)

    @classmethod
    def driver_loop(cls):
        rate = rospy.Rate(RATE)
        last = time.monotonic()
        while cls.running and not rospy.is_shutdown():
            now = time.monotonic()
            with cls.lock:
                cls.plant.step(now - last)
                p = list(cls.plant.p)
            last = now
            if cls.states_paused:
                rate.sleep()
                continue
            msg = ActuatorStates()
            msg.header.stamp = rospy.Time.now()
            msg.name = cls.state_names
            n = len(msg.name)
            msg.pressure = p + [float("nan")] * len(cls.others)
            msg.length = [0.01] * n
            msg.length_rate = [0.0] * n
            msg.force = [0.0] * n
            msg.command = [0.0] * n
            msg.supply_pressure = SUPPLY
            cls.state_pub.publish(msg)
            try:
                rate.sleep()
            except rospy.ROSInterruptException:
                return

    # --- helpers -------------------------------------------------------------------------
    def reference(self, forces, steps=20, dt=0.01, names=None, flat=None, shift=0.0):
        names = names if names is not None else self.pool + self.others
        msg = ForceReference()
        msg.header.stamp = rospy.Time.now() + rospy.Duration(shift)
        msg.dt = dt
        msg.steps = steps
        msg.name = names
        msg.force = flat if flat is not None else [forces[j] for _ in range(steps) for j in range(len(names))]
        self.ref_pub.publish(msg)

    def commands_between(self, t0, t1):
        with self.lock:
            return [m for (t, m) in self.commands if t0 <= t <= t1]

    def latest_status(self, name=None):
        name = name or rospy.get_param("~pool_name", "/pool_test")
        with self.lock:
            mine = [s for s in self.diagnostics if s.name == name]
        return mine[-1] if mine else None

    def wait_for(self, predicate, timeout, what):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return
            time.sleep(0.02)
        self.fail("timed out waiting for " + what)

    # --- the test ------------------------------------------------------------------------
    def test_1_reference_to_valve_commands(self):
        self.wait_for(lambda: len(self.commands_between(0, 1e18)) > 0, 30.0, "the first valve command")
        # Before any reference the pool vents its cylinders.
        time.sleep(0.2)
        first = self.commands_between(0, 1e18)[-1]
        self.assertEqual(list(first.volts), [EXHAUST] * len(self.pool))

        # Constant force references, refreshed at 20 Hz as the MPC would.
        forces_pool = [8.0, 4.0, 60.0]  # N: about 126 / 63 / 48 kPa gauge
        forces = forces_pool + [5.0] * len(self.others)
        start = time.monotonic()
        while time.monotonic() - start < 3.0:
            self.reference(forces)
            time.sleep(0.05)
        t_end = time.monotonic()
        window = self.commands_between(start + 1.0, t_end)

        # Rate from the publication stamps over ~2 s.
        stamps = [m.header.stamp.to_sec() for m in window]
        rate = (len(stamps) - 1) / (stamps[-1] - stamps[0])
        rospy.loginfo("valve command rate %.2f Hz over %d messages", rate, len(stamps))
        self.assertAlmostEqual(rate, self.rate, delta=0.05 * self.rate)
        gaps = [b - a for a, b in zip(stamps, stamps[1:])]
        self.assertLess(max(gaps), 5 * 1.0 / self.rate, "a gap of more than 5 periods")
        # Ticks sit on the pool's phase of the period grid (~tick_phase): the stamp is the
        # tick's wake-up time, so it is the grid point plus the wake-up latency.
        period = 1.0 / self.rate
        late = sorted((t - self.tick_phase * period) % period for t in stamps)
        rospy.loginfo("ticks %.3f ms (median) after their phase %.2f of the period",
                      late[len(late) // 2] * 1e3, self.tick_phase)
        self.assertLess(late[len(late) // 2], 1e-3, "ticks are not on the ~tick_phase grid")

        for m in window:
            # By index (resolved once from the actuator-state order), not by name.
            self.assertEqual(len(m.name), 0)
            self.assertEqual(sorted(self.state_names[i] for i in m.index), sorted(self.pool))
            self.assertEqual(len(m.index), len(self.pool))
            self.assertEqual(len(m.volts), len(self.pool))
            for v in m.volts:
                self.assertTrue(math.isfinite(v))
                self.assertGreaterEqual(v, -5.0)
                self.assertLessEqual(v, 5.0)
        # Tracking (exhaust would be -5): commands within the controller's +-2 V box.
        for m in window[-50:]:
            for v in m.volts:
                self.assertGreaterEqual(v, -2.0)
                self.assertLessEqual(v, 2.0)
        # The loop closed: the simulated tendon forces are near the references.
        with self.lock:
            p = list(self.plant.p)
        for name, pi, area, f in zip(self.pool, p, self.bores, forces_pool):
            force = (pi - ATM) * area
            rospy.loginfo("%s: force %.2f N for reference %.2f N", name, force, f)
            self.assertAlmostEqual(force, f, delta=0.25 * f, msg=name)

        # A negative force is clamped to 0 N (and counted); this is the last valid reference.
        t_bad = time.monotonic()
        self.reference([-3.0] + forces[1:])
        # Bad references: NaN, wrong length, unknown name, a stamp 10 s ahead of the clock
        # (e.g. wall time under sim time), one whose trajectory ended 5 s ago. The pool keeps
        # its last plan.
        self.reference([float("nan")] + forces[1:])
        self.reference(forces, flat=[1.0, 2.0, 3.0])
        self.reference(forces[:3], names=["A_FFJ2_flex", "A_NOSUCH_flex", "A_ARJ1_flex"])
        self.reference(forces, shift=10.0)
        self.reference(forces, shift=-5.0)
        # An actuator state measured 1 s ago is stale on arrival: rejected, counted.
        stale = ActuatorStates()
        stale.header.stamp = rospy.Time.now() - rospy.Duration(1.0)
        stale.name = self.state_names
        stale.pressure = [ATM] * len(self.state_names)
        stale.supply_pressure = SUPPLY
        self.state_pub.publish(stale)
        time.sleep(0.35)
        kept = self.commands_between(t_bad + 0.05, t_bad + 0.3)
        self.assertGreater(len(kept), 0.25 * self.rate * 0.8)
        for m in kept:
            for v in m.volts:
                self.assertTrue(-2.0 <= v <= 2.0, "pool dropped its plan before the timeout: %r" % (m.volts,))

        # After the timeout (measured from the last valid reference) every cylinder exhausts.
        time.sleep(self.timeout + 0.3)
        after = self.commands_between(t_bad + self.timeout + 0.2, time.monotonic())
        self.assertGreater(len(after), 0.2 * self.rate * 0.8)
        for m in after:
            self.assertEqual(list(m.volts), [EXHAUST] * len(self.pool))

        # Diagnostics count the rejections by reason and report the timings.
        def counted():
            s = self.latest_status()
            if s is None:
                return False
            kv = {x.key: x.value for x in s.values}
            return (int(kv.get("references_rejected_total", "0")) >= 5 and
                    int(kv.get("states_rejected_stale", "0")) >= 1)
        self.wait_for(counted, 3.0, "diagnostics with the rejections")
        kv = {x.key: x.value for x in self.latest_status().values}
        self.assertEqual(kv["references_rejected_non_finite"], "1")
        self.assertEqual(kv["references_rejected_length"], "1")
        self.assertEqual(kv["references_rejected_unknown_name"], "1")
        self.assertEqual(kv["references_rejected_stamp_future"], "1")
        self.assertEqual(kv["references_rejected_stamp_past"], "1")
        self.assertEqual(kv["references_rejected_total"], "5")
        self.assertEqual(kv["references_clamped_negative"], "1")
        self.assertGreaterEqual(int(kv["states_rejected_stale"]), 1)
        self.assertEqual(kv["states_rejected_duplicate_name"], "0")
        self.assertEqual(kv["addressing"], "index")
        self.assertEqual(kv["nonfinite_commands"], "0")
        for key in ("solve_time", "policy_lag", "tracking_rmse_N", "publish_rate_hz"):
            self.assertIn(key, kv)
        rospy.loginfo("diagnostics: %s", kv)

    def test_2_bad_configuration_stops_the_node(self):
        if not rospy.get_param("~check_bad_config", False):
            self.skipTest("checked by pool.test")
        bad_yaml = tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False)
        bad_yaml.write("parametric:\n  default: {c2: 0.0, c3: 2.0, c4: 0.5, c5: 0, c6: 0, c8: 0.2, c9: 10, cg: 0.3}\n")
        bad_yaml.close()
        # Private parameters go through the parameter server (roscpp's _name:=value cannot
        # express lists).
        cases = [
            ({"cylinders": ["A_FFJ2_flex"], "params_file": bad_yaml.name}, "parametric.default.c7"),
            ({"cylinders": ["A_FFJ2_flex", "A_NOSUCH_ext"]}, "A_NOSUCH_ext"),
            ({"cylinders": ["A_FFJ2_flex"], "controller": "mpc"}, "controller"),
            ({"pool": 9}, "pool"),
            ({"cylinders": ["A_FFJ2_flex"], "ilqg": {"horizon": 0}}, "horizon"),
            ({"cylinders": ["A_FFJ2_flex"], "reference_timout": 1.0}, "reference_timout"),
            ({"cylinders": ["A_FFJ2_flex"], "tick_phase": 1.5}, "tick_phase"),
            # A group: a cylinder in two members (one command names each once), a thread
            # setting on a member (the group has one tick), a member without cylinders.
            ({"members": ["a", "b"], "a": {"cylinders": ["A_FFJ2_flex"]},
              "b": {"cylinders": ["A_FFJ2_ext", "A_FFJ2_flex"]}}, "/b/cylinders"),
            ({"members": ["a", "b"], "a": {"cylinders": ["A_FFJ2_flex"]},
              "b": {"cylinders": ["A_FFJ2_ext"], "rate": 100}}, "/b/rate"),
            ({"members": ["a", "b"], "a": {"cylinders": ["A_FFJ2_flex"]}}, "/b/cylinders"),
            ({"members": ["a"], "a": {"cylinders": ["A_FFJ2_flex"], "ilqg": {"horizon": 0}}}, "/a/ilqg: horizon"),
        ]
        try:
            for i, (params, field) in enumerate(cases):
                name = "bad_pool_%d" % i
                for key, value in params.items():
                    rospy.set_param("/%s/%s" % (name, key), value)
                proc = subprocess.run(["rosrun", "adroit_pneumatics", "pool_node", "__name:=" + name],
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=30)
                self.assertNotEqual(proc.returncode, 0, params)
                lines = [l for l in (proc.stdout + proc.stderr).splitlines() if "FATAL" in l]
                self.assertEqual(len(lines), 1, proc.stdout + proc.stderr)
                self.assertIn(field, lines[0])
                self.assertIn("bad parameter", lines[0])
                rospy.loginfo("%s", lines[0])
        finally:
            os.unlink(bad_yaml.name)

    def test_3_group_one_command_and_exhaust_on_a_stale_state(self):
        if not self.members:
            self.skipTest("a single pool (pool.test, pool_nodelet.test)")
        forces = [8.0, 4.0, 60.0] + [5.0] * len(self.others)

        def drive(seconds):
            start = time.monotonic()
            while time.monotonic() - start < seconds:
                self.reference(forces)
                time.sleep(0.05)
            return start

        start = drive(1.5)
        driven = self.commands_between(start + 1.0, time.monotonic())
        # One message per tick of the group (not one per pool): distinct stamps a period apart,
        # each naming every cylinder of the group once.
        stamps = [m.header.stamp.to_sec() for m in driven]
        self.assertEqual(len(set(stamps)), len(stamps), "two commands for one tick")
        self.assertAlmostEqual((len(stamps) - 1) / (stamps[-1] - stamps[0]), self.rate, delta=0.05 * self.rate)
        for m in driven:
            self.assertEqual(sorted(self.state_names[i] for i in m.index), sorted(self.pool))
            for v in m.volts:
                self.assertTrue(-2.0 <= v <= 2.0, "not driven: %r" % (m.volts,))

        # The driver falls silent while the references go on: once the last state is older
        # than state_timeout (0.05 s), every cylinder of every pool exhausts.
        type(self).states_paused = True
        stop = drive(0.5)
        stale = self.commands_between(stop + 0.15, time.monotonic())
        type(self).states_paused = False
        self.assertGreater(len(stale), 0.3 * self.rate * 0.8)
        for m in stale:
            self.assertEqual(list(m.volts), [EXHAUST] * len(self.pool))
        # Fresh states again: the pools drive again.
        back = drive(1.0)
        for m in self.commands_between(back + 0.5, time.monotonic()):
            for v in m.volts:
                self.assertTrue(-2.0 <= v <= 2.0, "not driven again: %r" % (m.volts,))

        # One status per pool, named as the pool node it replaces, with its own cylinders.
        def reported():
            return all(self.latest_status(name) is not None for name, _ in self.members)
        self.wait_for(reported, 3.0, "a status of every pool of the group")
        for name, cylinders in self.members:
            kv = {x.key: x.value for x in self.latest_status(name).values}
            self.assertEqual(kv["cylinders"].split(), cylinders, name)
            self.assertIn("%d pools" % len(self.members), kv["group"])
            self.assertGreater(int(kv["states_accepted"]), 0, name)
            rospy.loginfo("%s: %s", name, kv)


if __name__ == "__main__":
    rospy.init_node("pool_rostest")
    rostest.rosrun("adroit_pneumatics", "pool_rostest", PoolTest)
