#!/usr/bin/python3
"""view.launch publishes tf for every link; distances match the kinematics reference."""
import math
import unittest

import rospy
import rostest
import tf2_ros


class ViewTf(unittest.TestCase):
    def setUp(self):
        self.buffer = tf2_ros.Buffer()
        self.listener = tf2_ros.TransformListener(self.buffer)

    def lookup(self, parent, child):
        return self.buffer.lookup_transform(parent, child, rospy.Time(0), rospy.Duration(20)).transform.translation

    def test_finger_joints_where_the_reference_puts_them(self):
        # kinematics reference 1e: zero-pose DIP pivots in the palm frame
        expected = {"ffdistal": (0.033, 0, 0.165), "lfdistal": (-0.034, 0, 0.158),
                    "thdistal": (0.0835, -0.009, 0.0785)}
        for link, (x, y, z) in expected.items():
            t = self.lookup("palm", link)
            self.assertAlmostEqual(t.x, x, delta=1e-3, msg=link)
            self.assertAlmostEqual(t.y, y, delta=1e-3, msg=link)
            self.assertAlmostEqual(t.z, z, delta=1e-3, msg=link)

    def test_whole_chain_reaches_world(self):
        t = self.lookup("world", "thdistal")
        self.assertTrue(all(math.isfinite(v) for v in (t.x, t.y, t.z)))
        # The arm base stands 0.85 m behind the table centre (scene arm_hand).
        base = self.lookup("world", "arm_base")
        self.assertAlmostEqual(base.y, -0.85, delta=1e-6)


if __name__ == "__main__":
    rospy.init_node("test_view_tf")
    rostest.rosrun("adroit_launch", "view_tf", ViewTf)
