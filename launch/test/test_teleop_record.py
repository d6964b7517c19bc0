#!/usr/bin/python3
"""teleop.launch record:=true records one demonstration bag while the glove moves the hand;
the demos tool validates it, exports it as the (x_t, u_t) matrices the learner reads, and
replays it into the running simulation driver, which reproduces the recorded joint states."""
import glob
import os
import subprocess
import time
import unittest

import rosnode
import rospy
import rostest
from sensor_msgs.msg import JointState


def demos(*args):
    return subprocess.run(["rosrun", "adroit_teleop", "demos"] + list(args), capture_output=True, text=True,
                          timeout=120)


def read_matrices(path):
    """Blocks of a MatrixFile (adroit_learning/matrix_file.h): name rows cols, then the numbers."""
    tokens = []
    with open(path) as f:
        for line in f:
            tokens += line.split("#", 1)[0].split()
    blocks, i = {}, 0
    while i < len(tokens):
        name, rows, cols = tokens[i], int(tokens[i + 1]), int(tokens[i + 2])
        values = [float(v) for v in tokens[i + 3:i + 3 + rows * cols]]
        blocks[name] = [values[r * cols:(r + 1) * cols] for r in range(rows)]
        i += 3 + rows * cols
    return blocks


class TeleopRecord(unittest.TestCase):
    def test_record_validate_export_replay(self):
        prefix = rospy.get_param("/bag_prefix")
        joints = rospy.wait_for_message("/adroit/joint_states", JointState, timeout=60)
        time.sleep(8.0)  # the emulated glove moves the hand; rosbag records
        # Stopping the recorder the way a user does (rosnode kill / Ctrl-C) closes the bag.
        rosnode.kill_nodes(["/record_demo"])
        deadline = time.time() + 20
        bags = []
        while time.time() < deadline and not bags:
            bags = glob.glob(prefix + "_*.bag")
            time.sleep(0.2)
        self.assertEqual(len(bags), 1, glob.glob(prefix + "*"))
        bag = bags[0]

        v = demos("validate", bag)
        self.assertEqual(v.returncode, 0, v.stdout + v.stderr)
        self.assertIn("ok", v.stdout)

        out = prefix + "_demo.txt"
        e = demos("export", bag, "--out", out, "--dt", "0.04")
        self.assertEqual(e.returncode, 0, e.stdout + e.stderr)
        m = read_matrices(out)
        nj, cylinders = len(joints.name), 40
        # x = [q | object pose (6) | qdot | object velocity (6) | pressures], u = tensions.
        self.assertEqual(len(m["X"][0]), 2 * nj + 12 + cylinders)
        self.assertEqual(len(m["U"][0]), cylinders)
        self.assertEqual(len(m["X"]), len(m["U"]))
        self.assertGreater(len(m["X"]), 150)  # > 6 s at 25 Hz
        self.assertAlmostEqual(m["dt"][0][0], 0.04)
        # The hand moved, and the tensions pulled (above the 0.3 N minimum somewhere).
        index = joints.name.index("FFJ2")
        ffj2 = [row[index] for row in m["X"]]
        self.assertGreater(max(ffj2) - min(ffj2), 0.5)
        self.assertGreater(max(max(row) for row in m["U"]), 1.0)

        # Replay sets the driver's state sample by sample and compares what it then reports
        # (joint noise 3.5 mrad and 1.5 mrad steps of sensor realism: the worst of a few hundred
        # samples stays within 0.03 rad).
        r = demos("replay", bag, "--every", "25", "--tolerance", "0.03")
        self.assertEqual(r.returncode, 0, r.stdout + r.stderr)


if __name__ == "__main__":
    rospy.init_node("test_teleop_record")
    rostest.rosrun("adroit_launch", "teleop_record", TeleopRecord)
