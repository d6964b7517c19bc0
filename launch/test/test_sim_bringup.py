#!/usr/bin/python3
"""sim.launch brings the simulated robot up: the driver streams, tf reaches the fingertips
through robot_state_publisher and the object through the driver, diagnostics say running."""
import unittest

import numpy as np
import rospy
import rostest
import tf2_ros
from adroit_msgs.msg import ActuatorStates
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState


class SimBringup(unittest.TestCase):
    def test_streams_and_tf(self):
        js = rospy.wait_for_message("/adroit/joint_states", JointState, timeout=30)
        self.assertEqual(len(js.name), 28)
        acts = rospy.wait_for_message("/adroit/actuator_states", ActuatorStates, timeout=10)
        self.assertEqual(len(acts.pressure), 48)
        self.assertGreater(acts.supply_pressure, 500e3)
        buf = tf2_ros.Buffer()
        tf2_ros.TransformListener(buf)
        tip = buf.lookup_transform("world", "thdistal", rospy.Time(0), rospy.Duration(20)).transform.translation
        self.assertLess(abs(tip.x), 1.0)
        # The object's tf is the driver's odometry: the pose of a message equals the transform
        # at its stamp (where the ball is depends on where it fell: with nothing holding the arm
        # up it may end anywhere on the table or beyond).
        odom = rospy.wait_for_message("/adroit/object/odom", Odometry, timeout=10)
        obj = buf.lookup_transform("world", "object", odom.header.stamp, rospy.Duration(5)).transform
        p = odom.pose.pose.position
        np.testing.assert_allclose([obj.translation.x, obj.translation.y, obj.translation.z], [p.x, p.y, p.z], atol=1e-6)
        q = odom.pose.pose.orientation
        np.testing.assert_allclose(abs(np.dot([obj.rotation.x, obj.rotation.y, obj.rotation.z, obj.rotation.w],
                                              [q.x, q.y, q.z, q.w])), 1.0, atol=1e-6)
        # The driver and, in pneumatic mode, the six pools report on /adroit/diagnostics.
        statuses = {}
        sub = rospy.Subscriber("/adroit/diagnostics", DiagnosticArray,
                               lambda msg: statuses.update({st.name: st.message for st in msg.status}))
        deadline = rospy.Time.now() + rospy.Duration(15)
        while rospy.Time.now() < deadline and not ("adroit_sim" in statuses and len(statuses) >= 7):
            rospy.sleep(0.1)
        sub.unregister()
        self.assertEqual(statuses.get("adroit_sim"), "running", statuses)
        pools = [name for name in statuses if "pool" in name]
        self.assertEqual(len(pools), 6, statuses)


if __name__ == "__main__":
    rospy.init_node("test_sim_bringup")
    rostest.rosrun("adroit_launch", "sim_bringup", SimBringup)
