#!/usr/bin/env python3
"""The MPC closed loop in lockstep with the simulation driver (mpc_lockstep.test): the dropped
bottle is caught and ends near its goal, within a bounded wall time; bad input is refused."""
import math
import threading
import time
import unittest

import rospy
import rostest
from adroit_msgs.srv import SetTask, SetTaskRequest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Pose, PoseStamped
from nav_msgs.msg import Odometry


class MpcLockstepTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_mpc_lockstep")
        cls.lock = threading.Lock()
        cls.odom = []  # (stamp, (x, y, z))
        cls.diag = {}
        cls.subs = [
            rospy.Subscriber("/adroit/object/odom", Odometry, cls._odom, queue_size=1000),
            rospy.Subscriber("/adroit/diagnostics", DiagnosticArray, cls._diag, queue_size=50),
        ]
        rospy.wait_for_service("/adroit/mpc/set_task", timeout=60)
        cls.set_task = rospy.ServiceProxy("/adroit/mpc/set_task", SetTask)
        cls.goal_pub = rospy.Publisher("/adroit/mpc/goal", PoseStamped, queue_size=5)

    @classmethod
    def _odom(cls, msg):
        p = msg.pose.pose.position
        with cls.lock:
            cls.odom.append((msg.header.stamp.to_sec(), (p.x, p.y, p.z)))

    @classmethod
    def _diag(cls, msg):
        for status in msg.status:
            if status.name == "adroit_mpc":
                with cls.lock:
                    cls.diag = {kv.key: kv.value for kv in status.values}

    def diag_value(self, key):
        with self.lock:
            return self.diag.get(key)

    def wait_diag(self, key, predicate, timeout):
        deadline = time.time() + timeout
        while time.time() < deadline:
            v = self.diag_value(key)
            if v is not None and predicate(float(v)):
                return float(v)
            time.sleep(0.05)
        self.fail("diagnostics %s never satisfied the check (last %s)" % (key, self.diag_value(key)))

    def test_1_unknown_task_refused(self):
        res = self.set_task(SetTaskRequest(task="juggle"))
        self.assertFalse(res.success)
        self.assertIn("unknown task 'juggle'", res.message)

    def test_2_nan_goal_rejected(self):
        req = SetTaskRequest(task="catch")
        req.goal.position.x = float("nan")
        req.goal.orientation.w = 1.0
        res = self.set_task(req)
        self.assertFalse(res.success)
        self.assertIn("NaN", res.message)
        # The goal topic: rejected and counted in diagnostics.
        self.wait_diag("rejected_goal", lambda v: v >= 1, 10)
        before = float(self.diag_value("rejected_goal"))
        msg = PoseStamped()
        msg.header.frame_id = "world"
        msg.pose.position.z = float("nan")
        msg.pose.orientation.w = 1.0
        deadline = time.time() + 5
        while self.goal_pub.get_num_connections() == 0 and time.time() < deadline:
            time.sleep(0.05)
        self.goal_pub.publish(msg)
        self.wait_diag("rejected_goal", lambda v: v >= before + 1, 10)

    def test_3_bottle_caught_and_brought_to_goal(self):
        """The bottle is dropped onto the palm-up hand at the start of the run (the driver
        starts paused; the MPC steps it). Without control it rolls off the palm and falls
        to the floor; the MPC must catch it and hold it near the goal."""
        goal = rospy.get_param("~goal")
        sim_seconds = rospy.get_param("~sim_seconds", 1.5)
        wall_timeout = rospy.get_param("~wall_timeout", 60.0)
        min_height = rospy.get_param("~min_height")
        tolerance = rospy.get_param("~tolerance")
        start = time.time()
        while time.time() - start < 20:
            with self.lock:
                if self.odom:
                    t0, p0 = self.odom[0]
                    break
            time.sleep(0.01)
        else:
            self.fail("no object odometry: the MPC does not step the driver")
        while True:
            with self.lock:
                t1, p1 = self.odom[-1]
            if t1 >= sim_seconds:
                break
            self.assertLess(time.time() - start, wall_timeout,
                            "closed loop too slow: %.3f simulated s in %.0f wall s" % (t1, wall_timeout))
            time.sleep(0.05)
        with self.lock:  # the first sample at the end time: the lockstep run is reproducible
            t1, p1 = next((t, p) for t, p in self.odom if t >= sim_seconds)
            lowest = min(p[2] for t, p in self.odom if t <= t1)
        d0, d1 = math.dist(p0, goal), math.dist(p1, goal)
        rospy.loginfo("bottle %.4f m from the goal at %.3f s, %.4f m at %.3f s, lowest z %.3f m (%.1f wall s)",
                      d0, t0, d1, t1, lowest, time.time() - start)
        self.assertGreater(lowest, min_height, "the bottle fell off the hand (lowest z %.3f m)" % lowest)
        self.assertLess(d1, tolerance, "the bottle is %.4f m from its goal after %.2f s" % (d1, t1))
        self.assertLess(d1, d0, "the bottle did not approach its goal: %.4f -> %.4f m" % (d0, d1))
        self.wait_diag("policies_published", lambda v: v > 0, 5)
        self.wait_diag("commands_sent", lambda v: v > 0, 5)


if __name__ == "__main__":
    rostest.rosrun("adroit_mpc", "mpc_lockstep", MpcLockstepTest)
