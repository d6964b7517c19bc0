#!/usr/bin/python3
"""Glove teleop on the robot's stack (teleop.launch robot:=emulated): started as an operator starts
the robot (the driver in its safe state until /adroit/estop_release once the glove and the pools
are up, then the dead-man pressed), the teleop node's force references reach the pools, whose
valve commands move the emulated robot's fingers after the calibrated glove targets (the same
criterion as on the simulation, test_teleop.py), and the robot never enters its safe state
again."""
import os
import sys
import time
import unittest

import rospkg
import rospy
import rostest
from adroit_msgs.msg import ForceReference
from std_msgs.msg import Bool
from std_srvs.srv import SetBool, Trigger

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # catkin's relay runs this file from devel
sys.path.insert(0, os.path.join(rospkg.RosPack().get_path("adroit_core"), "tools"))  # machine_probe.py
from machine_probe import MachineProbe, mark_probe_skips, unless_the_machine_slowed  # noqa: E402
from test_teleop import FOLLOWED, Nearest, Recorder  # noqa: E402


class TeleopHardware(unittest.TestCase):
    def test_the_glove_moves_the_emulated_robot(self):
        probe = MachineProbe()
        with unless_the_machine_slowed(self, probe):
            self.judge(probe)

    def judge(self, probe):
        rec = Recorder(streams=("safe", "targets", "joints"))
        references = []
        rospy.Subscriber("/adroit/force_reference", ForceReference, lambda m: references.append(time.monotonic()))
        self.assertTrue(rospy.wait_for_message("/adroit/safe_state", Bool, timeout=60).data,
                        "start_in_safe_state: the robot should start with its valves exhausted")
        rospy.wait_for_message("/adroit/joint_states", rospy.AnyMsg, timeout=60)
        rospy.wait_for_message("/adroit_teleop/glove", rospy.AnyMsg, timeout=60)
        rospy.wait_for_message("/adroit/valve_command", rospy.AnyMsg, timeout=60)  # the pools are up
        rospy.wait_for_service("/adroit/estop_release", timeout=30)
        released = rospy.ServiceProxy("/adroit/estop_release", Trigger)()
        self.assertTrue(released.success, released.message)
        rospy.wait_for_service("/adroit_teleop/enable", timeout=30)
        pressed = rospy.ServiceProxy("/adroit_teleop/enable", SetBool)(True)
        self.assertTrue(pressed.success, pressed.message)
        rospy.wait_for_message("/adroit/force_reference", ForceReference, timeout=60)
        start = time.monotonic()
        time.sleep(7.0)
        end = time.monotonic()  # the window judged; what follows is this test computing
        probe.stop()
        self.assertGreater(len([t for t in references if t > start]) / 7.0, 100, "force references below the glove rate")
        targets = rec.since(rec.targets, start + 1.0)
        joints = Nearest(rec.since(rec.joints, start + 0.5))
        for j in FOLLOWED:
            errors, wanted = [], []
            for target in targets[::10]:
                want = dict(zip(target.name, target.position))[j]
                have = joints.at(target.header.stamp + rospy.Duration(0.1))[j]
                errors.append(have - want)
                wanted.append(want)
            rms = (sum(e * e for e in errors) / len(errors)) ** 0.5
            swept = max(wanted) - min(wanted)
            self.assertGreater(swept, 0.5, "%s: the glove target hardly moved (%.2f rad)" % (j, swept))
            self.assertLess(rms, 0.2 * swept, "%s: rms error %.3f rad over a sweep of %.2f rad" % (j, rms, swept))
            print("%s: rms error %.1f deg over a sweep of %.0f deg" % (j, rms * 57.3, swept * 57.3))
        with rec.lock:
            safe = [m.data for t, m in rec.safe if start <= t <= end]
        self.assertNotIn(True, safe, "the robot entered its safe state")


if __name__ == "__main__":
    rospy.init_node("test_teleop_hardware")
    rostest.rosrun("adroit_launch", "teleop_hardware", TeleopHardware)
    mark_probe_skips()
