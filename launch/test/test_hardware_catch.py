#!/usr/bin/python3
"""The catch on the hardware driver over the emulated CAN buses, run as the README demo runs it
(demo_report): the driver starts in its safe state and refuses the simulation's
set_object_pose; demo_report releases it once the pools command, places the bottle through the
emulator, and exits 0 only when the MPC planned and the robot never entered its safe state
after the release. Where the bottle ends is printed (whether it is caught in real time depends on
the planning latency of the machine: mpc_success measures it)."""
import os
import re
import subprocess
import sys
import time
import unittest

import rospkg
import rospy
import rostest
from adroit_msgs.srv import SetObjectPose, SetObjectPoseRequest
from nav_msgs.msg import Odometry
from std_msgs.msg import Bool

sys.path.insert(0, os.path.join(rospkg.RosPack().get_path("adroit_core"), "tools"))  # machine_probe.py
from machine_probe import MachineProbe, mark_probe_skips, unless_the_machine_slowed  # noqa: E402


class HardwareCatch(unittest.TestCase):
    def test_the_catch_runs_sound_on_the_emulated_robot(self):
        rospy.init_node("test_hardware_catch", anonymous=True)
        self.assertTrue(rospy.wait_for_message("/adroit/safe_state", Bool, timeout=60).data,
                        "start_in_safe_state: the robot should start with its valves exhausted")
        # The robot refuses to teleport its object; the lab's hand (the emulator) does not.
        rospy.wait_for_service("/adroit/set_object_pose", timeout=30)
        request = SetObjectPoseRequest()
        request.pose.position.x, request.pose.position.y, request.pose.position.z = 0.2, -0.2, 0.5
        request.pose.orientation.w = 1.0
        refused = rospy.ServiceProxy("/adroit/set_object_pose", SetObjectPose)(request)
        self.assertFalse(refused.success)
        placed = rospy.ServiceProxy("/adroit_can_emulator/set_object_pose", SetObjectPose)(request)
        self.assertTrue(placed.success, placed.message)
        # The motion capture sees it after its delay (5 ms): a message or two in flight may still
        # show the bottle where it was.
        deadline = time.monotonic() + 1.0
        odom = None
        while time.monotonic() < deadline and (odom is None or abs(odom.pose.pose.position.x - 0.2) > 0.01):
            odom = rospy.wait_for_message("/adroit/object/odom", Odometry, timeout=5)
        self.assertAlmostEqual(odom.pose.pose.position.x, 0.2, delta=0.01)
        self.assertAlmostEqual(odom.pose.pose.position.y, -0.2, delta=0.01)

        probe = MachineProbe()
        with unless_the_machine_slowed(self, probe):
            self.run_the_catch(probe)

    def run_the_catch(self, probe):
        proc = subprocess.run(
            ["rosrun", "adroit_launch", "demo_report.py", "__name:=demo_report_hw", "_drop_height:=0.07",
             "_watch:=3.0", "_driver:=adroit_hw", "_start_with:=estop_release",
             "_place_service:=/adroit_can_emulator/set_object_pose", "_wait:=90"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=200)
        probe.stop()
        self.assertEqual(proc.returncode, 0, proc.stdout)
        result = re.search(r"after 3.0 s it is ([0-9.]+) cm from the goal.*lowest height (-?[0-9.]+) m", proc.stdout)
        self.assertIsNotNone(result, proc.stdout)
        self.assertIn("safe_state: false", proc.stdout)
        print(f"catch on the emulated robot: {result.group(1)} cm from the goal, lowest {result.group(2)} m")


if __name__ == "__main__":
    rostest.rosrun("adroit_launch", "hardware_catch", HardwareCatch)
    mark_probe_skips()
