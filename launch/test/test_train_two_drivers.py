#!/usr/bin/python3
"""Training spread over two lockstep drivers: both drivers run rollouts (their clocks advance
by the rollouts they ran) and the iterations complete."""
import tempfile
import time
import unittest

import rospy
import rostest
from adroit_msgs.msg import TrainProgress
from adroit_msgs.srv import Train, TrainStatus
from rosgraph_msgs.msg import Clock


class TrainTwoDrivers(unittest.TestCase):
    def test_rollouts_run_on_both_drivers(self):
        rospy.wait_for_service("/adroit_learning/train", timeout=60)
        train = rospy.ServiceProxy("/adroit_learning/train", Train)
        status = rospy.ServiceProxy("/adroit_learning/status", TrainStatus)
        clocks = {}
        subs = [rospy.Subscriber(topic, Clock, lambda m, t=topic: clocks.__setitem__(t, m.clock.to_sec()))
                for topic in ("/clock", "/driver2/clock")]
        progress = []
        psub = rospy.Subscriber("/adroit_learning/progress", TrainProgress, progress.append)
        r = train(task="position_with_gravity", iterations=2, rollouts=4, seed=3,
                  output_dir=tempfile.mkdtemp(prefix="adroit_two_drivers_"))
        self.assertTrue(r.accepted, r.message)
        deadline = time.time() + 240
        while time.time() < deadline and status().state == "running":
            time.sleep(0.1)
        s = status()
        self.assertEqual(s.state, "finished", s.message)
        time.sleep(0.5)
        for sub in subs + [psub]:
            sub.unregister()
        self.assertEqual(len(progress), 2)
        self.assertTrue(all(p.ok for p in progress), [p.message for p in progress])
        # 4 rollouts per iteration, 2 per driver: each driver ran 2 x 2 rollouts of 2 s (T 50 x 40 ms).
        for topic in ("/clock", "/driver2/clock"):
            self.assertIn(topic, clocks)
            self.assertGreater(clocks[topic], 2 * 2 * 2.0 - 0.1, clocks)


if __name__ == "__main__":
    rospy.init_node("test_train_two_drivers")
    rostest.rosrun("adroit_launch", "train_two_drivers", TrainTwoDrivers)
