#!/usr/bin/python3
"""The calibration service end to end: a simulated glove (records on /adroit_teleop/glove
whose sensors are a known affine function of the pose being held) goes through start, record
for every pose of the shipped pose file, fit; the written YAML maps each pose's readings back
to its joint targets, and the teleop node uses it at once. Bad start-up input: a missing
calibration file stops the teleop node with a line naming it; a missing glove port keeps the
glove node up, reporting the port, and retrying."""
import os
import subprocess
import tempfile
import threading
import time
import unittest

import numpy as np
import rospy
import rostest
import yaml
from adroit_msgs.msg import GloveSensors
from adroit_msgs.srv import Calibrate

SENSORS = 22
# CyberGlove sensor -> ADROIT joint (adroit_teleop glove_layout.h); the simulated glove reads
# each sensor's joint with a gain and an offset, plus a little of the next sensor's joint.
LAYOUT = ["THJ4", "THJ1", "THJ0", "THJ3", "FFJ2", "FFJ1", "FFJ0", "MFJ2", "MFJ1", "MFJ0", "FFJ3",
          "RFJ2", "RFJ1", "RFJ0", "RFJ3", "LFJ2", "LFJ1", "LFJ0", "LFJ3", "LFJ4", "WRJ0", "WRJ1"]
UNSENSED = {"THJ2", "MFJ3"}


def load_poses():
    path = os.path.join(rospy.get_param("/teleop/poses"))
    with open(path) as f:
        data = yaml.safe_load(f)
    return data["joints"], data["poses"]


class SimulatedGlove:
    """Publishes records of the pose it is told to hold, at 100 Hz."""

    def __init__(self, joints):
        self.joints = joints
        self.pub = rospy.Publisher("/adroit_teleop/glove", GloveSensors, queue_size=10)
        self.q = np.zeros(len(joints))
        self.A = np.zeros((SENSORS, len(joints)))
        for s, name in enumerate(LAYOUT):
            j = joints.index(name)
            self.A[s, j] = 60.0                          # counts per rad
            self.A[s, (j + 1) % len(joints)] = 5.0       # cross-talk
        self.offset = np.full(SENSORS, 100.0)
        self.running = True
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def raw(self, q):
        return np.clip(np.round(self.A @ q + self.offset), 1, 255).astype(int)

    def run(self):
        record = 0
        while self.running and not rospy.is_shutdown():
            msg = GloveSensors()
            msg.header.stamp = rospy.Time.now()
            msg.record = record
            msg.raw = bytes(self.raw(self.q).tolist())
            self.pub.publish(msg)
            record += 1
            time.sleep(0.01)


class TeleopCalibration(unittest.TestCase):
    def test_1_calibration_service_recovers_the_poses(self):
        rospy.wait_for_service("/adroit_teleop/calibrate", timeout=30)
        calibrate = rospy.ServiceProxy("/adroit_teleop/calibrate", Calibrate)
        joints, poses = load_poses()
        glove = SimulatedGlove(joints)
        time.sleep(0.5)
        self.assertFalse(calibrate(action="record").success)  # not started
        self.assertFalse(calibrate(action="fly").success)
        r = calibrate(action="start")
        self.assertTrue(r.success, r.message)
        self.assertEqual(r.pose, poses[0]["name"])
        self.assertEqual(list(r.remaining), [p["name"] for p in poses])
        self.assertFalse(calibrate(action="fit").success)  # poses missing
        targets = {}
        for pose in poses:
            q = np.zeros(len(joints))
            for name, value in pose.get("targets", {}).items():
                q[joints.index(name)] = value
            targets[pose["name"]] = (q, set(pose.get("free", [])))
            glove.q = q
            time.sleep(0.15)  # the hand moves into the pose before the user says "record"
            r = calibrate(action="record")
            self.assertTrue(r.success, r.message)
        self.assertEqual(r.pose, "")
        out = os.path.join(tempfile.mkdtemp(prefix="adroit_calibration_"), "glove.yaml")
        r = calibrate(action="fit", output=out)
        self.assertTrue(r.success, r.message)
        glove.running = False
        with open(out) as f:
            fitted = yaml.safe_load(f)
        self.assertEqual(fitted["joints"], joints)
        W = np.array(fitted["W"], dtype=float).reshape(len(joints), SENSORS)
        b = np.array(fitted["b"], dtype=float)
        for name, (q, free) in targets.items():
            s = glove.raw(q) / 255.0
            got = W @ s + b
            for j, joint in enumerate(joints):
                if joint in free or joint in UNSENSED:
                    continue
                self.assertAlmostEqual(got[j], q[j], delta=0.05, msg="%s %s" % (name, joint))
        # The node runs on what it wrote.
        metadata = rospy.wait_for_message("/adroit_teleop/metadata", rospy.AnyMsg, timeout=5)
        self.assertIsNotNone(metadata)

    def test_2_missing_calibration_stops_the_node_naming_the_file(self):
        missing = "/tmp/adroit_no_such_calibration.yaml"
        p = subprocess.run(["rosrun", "adroit_teleop", "teleop_node", "__name:=teleop_bad",
                            "_calibration:=" + missing, "_scene:=teleop_tube"],
                           capture_output=True, text=True, timeout=60)
        self.assertNotEqual(p.returncode, 0)
        self.assertIn(missing, p.stdout + p.stderr)

    def test_3_missing_glove_port_is_reported_and_retried(self):
        port = "/tmp/adroit_no_such_glove"
        p = subprocess.Popen(["rosrun", "adroit_teleop", "glove_node", "__name:=glove_missing", "_port:=" + port],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        time.sleep(4.0)
        self.assertIsNone(p.poll(), "the glove node died on a missing port")
        p.terminate()
        out, _ = p.communicate(timeout=20)
        self.assertIn(port, out)
        self.assertIn("No such file", out)


if __name__ == "__main__":
    rospy.init_node("test_teleop_calibration")
    rostest.rosrun("adroit_launch", "teleop_calibration", TeleopCalibration)
