#!/usr/bin/python3
"""Learning from demonstrations end to end in its smallest configuration: 2 expert demonstrations
(recorded through the glove emulator, teleop and pools, under a ROS master of their own), a
library job of 2 local policies x 2 iterations started with rosservice, a 2 x 16 network
distilled from them, execute_policy of the network and of the library on the lockstep driver,
and pickup_eval over both. Bad demonstrations are refused with one line and train nothing."""
import math
import os
import re
import shutil
import subprocess
import tempfile
import threading
import time
import unittest

import rospy
import rostest
from adroit_msgs.msg import TrainProgress
from adroit_msgs.srv import ExecutePolicy, Train, TrainStatus

YAWS = (0.0, 18.0)
EXPERT_MASTER = "http://localhost:11417"  # the expert's own graph: its driver would clash with ours


def program(package, name):
    """A program of a package (rosrun's lookup, without a shell)."""
    out = subprocess.run(["catkin_find", "--first-only", "--libexec", package, name], capture_output=True, text=True)
    path = out.stdout.strip()
    if not path:
        raise RuntimeError("cannot find %s/%s" % (package, name))
    return path


def wait_until(predicate, timeout):
    deadline = time.time() + timeout
    while time.time() < deadline:
        if predicate():
            return True
        time.sleep(0.2)
    return predicate()


class PickupPipeline(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_pickup_pipeline")
        cls.dir = tempfile.mkdtemp(prefix="pickup_pipeline_")
        cls.demos = os.path.join(cls.dir, "demos")
        env = dict(os.environ, ROS_MASTER_URI=EXPERT_MASTER)
        cls.expert = subprocess.run([program("adroit_teleop", "pickup_expert"), "--out", cls.demos, "--yaws",
                                     ",".join("%g" % y for y in YAWS)], env=env, capture_output=True, text=True,
                                    timeout=240)
        for name in ("train", "status", "execute_policy"):
            rospy.wait_for_service("/adroit_learning/" + name, timeout=60)
        cls.train = rospy.ServiceProxy("/adroit_learning/train", Train)
        cls.status = rospy.ServiceProxy("/adroit_learning/status", TrainStatus)
        cls.execute = rospy.ServiceProxy("/adroit_learning/execute_policy", ExecutePolicy)
        cls.progress = []
        cls.lock = threading.Lock()
        cls.sub = rospy.Subscriber("/adroit_learning/progress", TrainProgress, cls.on_progress)

    @classmethod
    def on_progress(cls, msg):
        with cls.lock:
            cls.progress.append(msg)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.dir, ignore_errors=True)

    def test_0_the_expert_records_a_bag_per_angle(self):
        self.assertEqual(self.expert.returncode, 0, self.expert.stdout + self.expert.stderr)
        bags = sorted(f for f in os.listdir(self.demos) if f.endswith(".bag"))
        self.assertEqual(bags, ["pickup_yaw000.bag", "pickup_yaw018.bag"])

    def test_1_bad_demonstrations_are_refused_in_one_line(self):
        not_a_bag = os.path.join(self.dir, "notes.bag")
        with open(not_a_bag, "w") as f:
            f.write("a text file\n")
        empty = os.path.join(self.dir, "empty")
        os.makedirs(empty)
        for path, reason in ((not_a_bag, "not a rosbag file"), (empty, "a directory without demonstration bags"),
                             (os.path.join(self.dir, "missing.bag"), "missing.bag")):
            r = self.train(task="pickup", iterations=2, demonstrations=path)
            self.assertFalse(r.accepted, path)
            self.assertIn(reason, r.message)
            self.assertNotIn("\n", r.message.strip())
        self.assertNotEqual(self.status().state, "running")  # nothing was trained

    def test_2_library_job_trains_a_local_policy_per_demonstration(self):
        out = os.path.join(self.dir, "library")
        r = self.train(task="pickup", iterations=2, rollouts=2, seed=1, demonstrations=self.demos, output_dir=out)
        self.assertTrue(r.accepted, r.message)
        self.assertIn("2 local policies", r.message)
        self.assertTrue(wait_until(lambda: self.status().state != "running", 240), "the library job did not end")
        status = self.status()
        self.assertEqual(status.state, "finished", status.message)
        self.assertEqual((status.iteration, status.iterations), (4, 4))
        with open(os.path.join(out, "library.txt")) as f:
            entries = [line.split() for line in f if line.startswith("policy ")]
        self.assertEqual(len(entries), 2)
        for (_, yaw, path), expected in zip(entries, YAWS):
            self.assertAlmostEqual(float(yaw), expected, delta=1.0)  # the condition the demonstration started in
            self.assertTrue(os.path.isfile(os.path.join(out, path)), path)
        with self.lock:
            parts = sorted({(m.policy, m.policies) for m in self.progress if m.job_id == r.job_id})
            yaws = sorted({round(m.initial_object_yaw) for m in self.progress if m.job_id == r.job_id})
        self.assertEqual(parts, [(0, 2), (1, 2)])
        self.assertEqual(yaws, [0, 18])
        type(self).library = os.path.join(out, "library.txt")

    def test_3_network_distilled_and_every_kind_executed(self):
        net = os.path.join(self.dir, "tiny.policy")
        r = subprocess.run([program("adroit_learning", "train_network_policy"), "--library", self.library, "--task",
                            "pickup", "--observation", "partial", "--layers", "2", "--units", "16", "--rollouts", "2",
                            "--epochs", "3", "--workers", "2", "--out", net], capture_output=True, text=True, timeout=240)
        self.assertEqual(r.returncode, 0, r.stdout + r.stderr)
        self.assertRegex(r.stdout, r"RESULT adroit_learning/network_heldout_loss/partial_2x16 ")
        for path, kind in ((net, "network"), (self.library, "library")):
            answer = self.execute(policy_path=path, policy_type=kind, duration=0.0)
            self.assertTrue(answer.success, answer.message)
            self.assertTrue(math.isfinite(answer.final_cost), answer.message)
        type(self).network = net

    def test_4_evaluation_writes_the_tables(self):
        out = os.path.join(self.dir, "eval")
        r = subprocess.run([program("adroit_learning", "pickup_eval"), "--task", "pickup", "--policy",
                            "library=" + self.library, "--policy", "network=" + self.network, "--sweep-step", "90",
                            "--random", "2", "--workers", "2", "--no-plot", "--out", out],
                           capture_output=True, text=True, timeout=240)
        self.assertEqual(r.returncode, 0, r.stdout + r.stderr)
        with open(os.path.join(out, "sweep.csv")) as f:
            rows = [line.split(",") for line in f.read().splitlines()[1:]]
        self.assertEqual(sorted({row[0] for row in rows}), ["library", "network"])
        self.assertEqual(len(rows), 4)  # 2 policies x yaws 0 and 90
        self.assertRegex(r.stdout, r"RESULT adroit_learning/pickup_inference_p99/network [0-9.]+ ms")


if __name__ == "__main__":
    rostest.rosrun("adroit_launch", "test_pickup_pipeline", PickupPipeline)
