#!/usr/bin/python3
"""Reset restores the full state exactly (positions, velocities, pressures, object), to a
keyframe or to a given state, and /clock and message stamps never go backwards."""
import math
import os
import time
import unittest
import xml.etree.ElementTree as ET

import rospkg
import rospy
import rostest
from geometry_msgs.msg import Pose, Twist

from driver_client import DriverClient

N = 48


def model_layout(path):
    """(joint name, qpos size, dof size) in model order, read from the MJCF itself."""
    layout = []
    for el in ET.parse(path).getroot().find("worldbody").iter():
        if el.tag == "freejoint" or (el.tag == "joint" and el.get("type") == "free"):
            layout.append((el.get("name"), 7, 6))
        elif el.tag == "joint":
            layout.append((el.get("name"), 1, 1))
    return layout


class ResetState(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.d = DriverClient(object_odom=True)
        cls.d.pause(True)
        share = rospkg.RosPack().get_path("adroit_description")
        cls.layout = model_layout(os.path.join(share, "mjcf", "ball.xml"))

    def snapshot(self):
        """Message counts once the paused stream is quiet: messages of earlier steps may still
        be on their way when the step service answers, and must not pass for the reset's."""
        d = self.d
        topics = ("joint_states", "actuator_states", "object/odom")
        counts = {t: d.counted(t) for t in topics}
        while True:
            time.sleep(0.1)
            now = {t: d.counted(t) for t in topics}
            if now == counts:
                return counts
            counts = now

    def published(self, counts):
        d = self.d
        js = d.wait_new("joint_states", counts["joint_states"])
        acts = d.wait_new("actuator_states", counts["actuator_states"])
        odom = d.wait_new("object/odom", counts["object/odom"])
        p, q, v, w = odom.pose.pose.position, odom.pose.pose.orientation, odom.twist.twist.linear, odom.twist.twist.angular
        return {"names": list(js.name), "position": list(js.position), "velocity": list(js.velocity),
                "pressure": list(acts.pressure), "object": [p.x, p.y, p.z, q.w, q.x, q.y, q.z, v.x, v.y, v.z, w.x, w.y, w.z]}

    def reset(self, **kwargs):
        counts = self.snapshot()
        res = self.d.reset(**kwargs)
        self.assertTrue(res.success, res.message)
        return self.published(counts)

    def move_everything(self):
        """Valves open, the object thrown: the state changes everywhere."""
        d = self.d
        self.assertTrue(d.set_object_pose(self.object_pose(0.05, -0.1, 0.2), Twist()).success)
        for _ in range(10):
            d.command_all(3.0, N)
            time.sleep(0.02)
            d.step(20)

    def object_pose(self, x, y, z):
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = x, y, z
        pose.orientation.w = 1.0
        return pose

    def test_keyframe_reset_restores_exactly(self):
        first = self.reset(keyframe="rest")
        self.move_everything()
        second = self.reset(keyframe="rest")
        self.assertEqual(first, second)
        self.assertTrue(all(p == 101325.0 for p in second["pressure"]))

    def test_full_state_reset_restores_exactly_before_and_after(self):
        qpos, qvel, joints = [], [], {}
        for k, (name, nq, nv) in enumerate(self.layout):
            if nq == 7:  # the object: 5 cm above the table, rotated 90 deg about z, moving
                qpos += [0.02, -0.12, 0.1, math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)]
                qvel += [0.1, 0.0, 0.0, 0.0, 0.0, 0.5]
            else:
                joints[name] = (0.01 * (k % 7), -0.02 * (k % 5))
                qpos.append(joints[name][0])
                qvel.append(joints[name][1])
        pressure = [120e3 + 5e3 * i for i in range(N)]
        before = self.reset(qpos=qpos, qvel=qvel, pressure=pressure)
        # What was requested is what is published.
        for name, pos, vel in zip(before["names"], before["position"], before["velocity"]):
            self.assertEqual((pos, vel), joints[name], name)
        self.assertEqual(before["pressure"], pressure)
        self.assertEqual(before["object"][:7], qpos[28:35])
        self.assertAlmostEqual(before["object"][7], 0.0, delta=1e-12)  # world x velocity is body -y after 90 deg
        self.assertAlmostEqual(before["object"][8], -0.1, delta=1e-12)
        self.assertAlmostEqual(before["object"][12], 0.5, delta=1e-12)
        self.move_everything()
        after = self.reset(qpos=qpos, qvel=qvel, pressure=pressure)
        self.assertEqual(before, after)

    def test_bad_reset_requests_are_refused(self):
        self.assertFalse(self.d.reset(keyframe="nope").success)
        self.assertFalse(self.d.reset(qpos=[0.0, 1.0]).success)
        self.assertFalse(self.d.reset(pressure=[float("nan")] * N).success)
        self.assertTrue(self.d.step_srv(steps=1).success, "node still running")

    def test_finite_but_absurd_states_are_refused_and_nothing_faults(self):
        """qpos 1e300, qvel 1e6, an object 1e300 m away, a joint far outside its range or a
        non-unit quaternion would all fault the next step: each is refused with a message
        naming the joint, the robot keeps stepping, no fault latches and every published
        value stays finite."""
        d = self.d
        nq = sum(q for _, q, _ in self.layout)
        nv = sum(v for _, _, v in self.layout)
        self.assertTrue(d.reset(keyframe="home").success)
        cases = {"qpos 1e300": dict(qpos=[1e300] * nq),
                 "qvel 1e6": dict(qvel=[1e6] * nv)}
        quat_bad, out_of_range = [0.0] * nq, [0.0] * nq
        k = 0
        for name, q, _ in self.layout:
            if q == 7:
                quat_bad[k:k + 7] = [0.0, 0.0, 0.1, 0.5, 0.0, 0.0, 0.0]  # norm 0.5
                out_of_range[k:k + 7] = [0.0, 0.0, 0.1, 1.0, 0.0, 0.0, 0.0]
                quat_bad_joint = name
            k += q
        adr = 0
        for first_hinge, q, _ in self.layout:
            if q == 1:
                break
            adr += q
        out_of_range[adr] = 50.0  # rad: far outside any range
        cases["quaternion norm 0.5"] = dict(qpos=quat_bad)
        cases["joint 50 rad"] = dict(qpos=out_of_range)
        for what, state in cases.items():
            r = d.reset(**state)
            self.assertFalse(r.success, what)
            self.assertTrue(r.message, what)
        self.assertIn(quat_bad_joint, d.reset(qpos=quat_bad).message)
        self.assertIn(first_hinge, d.reset(qpos=out_of_range).message)
        far = Pose()
        far.position.x, far.orientation.w = 1e300, 1.0
        r = d.set_object_pose(pose=far, twist=Twist())
        self.assertFalse(r.success)
        self.assertIn("max_reset_distance", r.message)
        # The robot is untouched: it steps, publishes finite states and latches nothing.
        t, msg = d.step(50)
        self.assertTrue(all(math.isfinite(x) for x in msg.pressure + msg.force + msg.length))
        joints = d.wait_new("joint_states", 0)
        self.assertTrue(all(math.isfinite(x) for x in joints.position))
        diag = d.diagnostics()
        self.assertEqual(diag["fault_latched"], "false")
        self.assertEqual(diag["faults"], "0")
        self.assertEqual(diag["nonfinite_states_suppressed"], "0")

    def test_each_requested_step_publishes_its_own_clock(self):
        # Free-running lockstep publishes one /clock per chunk of steps; stepped on request,
        # one step at a time, every step's time must go out (a controller waits for it).
        d = self.d
        times = [d.step(1)[0] for _ in range(5)]
        deadline = time.time() + 5
        while time.time() < deadline:
            with d.lock:
                seen = [t for t in times if any(abs(c - t) < 1e-6 for c in d.clocks)]
            if len(seen) == len(times):
                break
            time.sleep(0.05)
        self.assertEqual(seen, times, "a requested step's /clock was not published")

    def test_lockstep_thread_runs_at_the_highest_normal_weight(self):
        values = self.d.diagnostics()
        if os.geteuid() == 0:  # permitted: applied
            self.assertEqual(values["thread_scheduling"], "normal, nice -20", str(values))
        else:  # not permitted: reported as not applied, and the node runs on
            self.assertEqual(values["thread_scheduling"], "normal", str(values))

    def test_zz_clock_and_stamps_never_go_back_and_lockstep_runs_fast(self):
        d = self.d
        t0 = d.step(1)[0]
        d.pause(False)
        start = time.time()
        time.sleep(1.0)
        d.pause(True)
        t1 = d.step(1)[0]
        self.assertGreater((t1 - t0) / (time.time() - start), 1.5, "lockstep should outrun real time")
        with d.lock:
            clocks = list(d.clocks)
            stamps = {k: list(v) for k, v in d.stamps.items()}
        self.assertGreater(len(clocks), 100)
        self.assertTrue(all(b >= a for a, b in zip(clocks, clocks[1:])), "/clock went backwards")
        for topic, s in stamps.items():
            self.assertTrue(all(b >= a for a, b in zip(s, s[1:])), "%s stamps went backwards" % topic)


if __name__ == "__main__":
    rospy.init_node("test_reset_state")
    rostest.rosrun("adroit_driver", "reset_state", ResetState)
