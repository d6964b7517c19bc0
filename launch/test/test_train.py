#!/usr/bin/python3
"""train.launch: a training job started with rosservice runs through the simulation driver in
lockstep, reports progress, lowers the cost, saves policies that execute_policy runs; bad
requests get a clear answer and disturb nothing: no driver step, no latched safe state, and
train, status and cancel agree that nothing runs."""
import csv
import math
import os
import tempfile
import threading
import time
import unittest

import rospy
import rostest
from adroit_msgs.msg import TrainProgress
from adroit_msgs.srv import ExecutePolicy, Train, TrainStatus
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger


def wall_wait(predicate, timeout):
    """Waits on wall time: the ROS clock only moves while the driver steps."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        if predicate():
            return True
        time.sleep(0.05)
    return predicate()


class DriverActivity:
    """Counts the lockstep driver's /clock and joint_states messages: both move only when it steps."""

    def __init__(self):
        self.lock = threading.Lock()
        self.clock = self.joints = 0
        self.subs = [rospy.Subscriber("/clock", Clock, self.on_clock),
                     rospy.Subscriber("/adroit/joint_states", JointState, self.on_joints)]

    def on_clock(self, _):
        with self.lock:
            self.clock += 1

    def on_joints(self, _):
        with self.lock:
            self.joints += 1

    def counts(self):
        with self.lock:
            return self.clock, self.joints

    def close(self):
        for sub in self.subs:
            sub.unregister()


class TrainThroughDriver(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        for name in ("train", "status", "cancel", "execute_policy"):
            rospy.wait_for_service("/adroit_learning/" + name, timeout=60)
        cls.train = rospy.ServiceProxy("/adroit_learning/train", Train)
        cls.status = rospy.ServiceProxy("/adroit_learning/status", TrainStatus)
        cls.cancel = rospy.ServiceProxy("/adroit_learning/cancel", Trigger)
        cls.execute = rospy.ServiceProxy("/adroit_learning/execute_policy", ExecutePolicy)
        cls.out = tempfile.mkdtemp(prefix="adroit_train_test_")

    def test_1_bad_requests_are_refused(self):
        r = self.train(task="juggle", iterations=3)
        self.assertFalse(r.accepted)
        self.assertIn("unknown task 'juggle'", r.message)
        self.assertIn("position_with_gravity", r.message)
        r = self.train(task="position_with_gravity", iterations=0)
        self.assertFalse(r.accepted)
        self.assertIn("iterations", r.message)
        r = self.train(task="position_with_gravity", iterations=3000000000)  # was "not positive"
        self.assertFalse(r.accepted)
        self.assertEqual(r.message, "iterations must be in [1, 10000], got 3000000000")
        r = self.train(task="position_with_gravity", iterations=3, rollouts=1)
        self.assertFalse(r.accepted)
        self.assertIn("samples", r.message)
        r = self.train(task="position_with_gravity", iterations=3, output_dir="/proc/adroit_learning_test")
        self.assertFalse(r.accepted)
        self.assertIn("/proc/adroit_learning_test", r.message)
        self.assertEqual(self.status().state, "idle")
        self.assertFalse(self.cancel().success)

    def test_2_trains_positioning_and_runs_the_policy(self):
        progress = []
        sub = rospy.Subscriber("/adroit_learning/progress", TrainProgress, progress.append)
        # A quote in the output directory once ended the plot command's shell quoting.
        marker = os.path.join(self.out, "injected")
        out = os.path.join(self.out, "job q'; touch " + marker + "; echo '")
        r = self.train(task="position_with_gravity", iterations=3, rollouts=5, seed=7, output_dir=out)
        self.assertTrue(r.accepted, r.message)
        self.assertTrue(r.job_id.startswith("position_with_gravity-"))
        busy = self.train(task="position_with_gravity", iterations=3, output_dir=out)
        self.assertFalse(busy.accepted)
        self.assertIn("a job is running", busy.message)
        self.assertEqual(self.status().state, "running")
        self.assertTrue(wall_wait(lambda: self.status().state != "running", 300), self.status())
        status = self.status()
        self.assertEqual(status.state, "finished", status.message)
        self.assertEqual(status.iteration, 3)
        self.assertTrue(wall_wait(lambda: len(progress) == 3, 10))
        sub.unregister()
        for p in progress:
            self.assertTrue(p.ok, p.message)
            self.assertEqual(p.samples, 5)
            self.assertGreater(p.rollout_s, 0)
            self.assertLessEqual(p.kl, 1.1 * p.epsilon + 1e-9)
        # Two KL-constrained updates lower the cost of the robot's rollouts.
        self.assertLess(progress[-1].cost_mean, progress[0].cost_mean)
        with open(os.path.join(out, "learning_curve.csv")) as f:
            rows = list(csv.DictReader(f))
        self.assertEqual([int(row["iteration"]) for row in rows], [0, 1, 2])
        self.assertAlmostEqual(float(rows[-1]["cost_mean"]), progress[-1].cost_mean, delta=1e-6 * progress[-1].cost_mean)
        self.assertTrue(os.path.getsize(os.path.join(out, "learning_curve.png")) > 1000)
        self.assertFalse(os.path.exists(marker))
        # The saved controller runs on the driver; its mean is at least as good as the noisy rollouts.
        result = self.execute(policy_path=progress[-1].policy_path, policy_type="tvlg")
        self.assertTrue(result.success, result.message)
        self.assertLess(result.final_cost, 1.5 * progress[-1].cost_mean)
        final = self.execute(policy_path=os.path.join(out, "final.tvlg"))
        self.assertTrue(final.success, final.message)

    def test_3_bad_policy_files_are_refused(self):
        path = os.path.join(self.out, "broken.tvlg")
        with open(path, "w") as f:
            f.write("adroit_tvlg_policy 1\ntask position_with_gravity\n")
        r = self.execute(policy_path=path)
        self.assertFalse(r.success)
        self.assertIn(path, r.message)
        self.assertIn("truncated", r.message)
        r = self.execute(policy_path=os.path.join(self.out, "none.tvlg"))
        self.assertFalse(r.success)
        self.assertIn("none.tvlg", r.message)
        self.assertEqual(self.status().state, "finished")  # nothing else disturbed

    def test_3b_refused_requests_change_nothing(self):
        final = os.path.join(self.out, "job q'; touch " + os.path.join(self.out, "injected") + "; echo '",
                             "final.tvlg")
        fifo = os.path.join(self.out, "policy.fifo")
        os.mkfifo(fifo)
        activity = DriverActivity()
        time.sleep(1.0)  # the subscriptions connect; the paused driver publishes nothing
        before = activity.counts()
        refused = [(dict(policy_path=final, duration=float("inf")), "got inf"),
                   (dict(policy_path=final, duration=float("nan")), "got nan"),
                   (dict(policy_path=final, duration=-1.0), "got -1"),
                   (dict(policy_path=final, duration=1e300), "got 1e+300"),
                   (dict(policy_path=os.path.join(self.out, "none.tvlg")), "none.tvlg: cannot open"),
                   (dict(policy_path=fifo), fifo + ": not a regular file (a FIFO)"),
                   (dict(policy_path=self.out), self.out + ": not a regular file (a directory)"),
                   (dict(policy_path="/dev/zero"), "/dev/zero: not a regular file (a character device)")]
        for request, message in refused:
            start = time.time()
            r = self.execute(**request)
            self.assertFalse(r.success, request)
            self.assertIn(message, r.message)
            self.assertTrue(math.isnan(r.final_cost))
            self.assertLess(time.time() - start, 5.0, request)  # a FIFO no longer blocks
            # Busy and idle answers agree: nothing runs.
            self.assertEqual(self.status().state, "finished")
            self.assertEqual(self.cancel().message, "no job is running")
        time.sleep(1.0)
        self.assertEqual(activity.counts(), before, "a refused request stepped the driver")
        # No latched watchdog or e-stop: the next request runs without a release.
        r = self.execute(policy_path=final, duration=1.0)
        self.assertTrue(r.success, r.message)
        self.assertIn("ran 25 steps", r.message)
        self.assertTrue(wall_wait(lambda: activity.counts()[0] > before[0], 5))  # the counter sees steps
        activity.close()

    def test_4_a_task_of_another_scene_fails_clearly(self):
        # The driver runs the hand scene; the tube tasks have the same joints but an object.
        r = self.train(task="rotate_vertical_cw", iterations=2, output_dir=os.path.join(self.out, "tube"))
        self.assertTrue(r.accepted, r.message)
        self.assertTrue(wall_wait(lambda: self.status().state != "running", 60))
        status = self.status()
        self.assertEqual(status.state, "failed")
        self.assertIn("start the driver with the task's scene", status.message)


if __name__ == "__main__":
    rospy.init_node("test_train")
    rostest.rosrun("adroit_launch", "train_through_driver", TrainThroughDriver)
