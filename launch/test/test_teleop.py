#!/usr/bin/python3
"""teleop.launch end to end with the glove emulator: records stream at the emulator's rate;
nothing is commanded while the dead-man is released; pressed, the simulated fingers follow
the calibrated glove targets and every command's latency is reported by the driver; the glove
unplugged stops the commands (the driver's watchdog takes over), and commanding resumes only
after the glove is back and the dead-man is pressed again."""
import bisect
import threading
import time
import unittest

import rospy
import rostest
import tf2_ros
from adroit_msgs.msg import CommandLatency, GloveSensors, TendonForceCommand
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

# The emulator unplugs 22 s after it starts, for 2.5 s (teleop.test).
UNPLUG_AFTER, UNPLUG_FOR = 22.0, 2.5
# Joints the synthetic glove sweeps over their whole range through the nominal calibration.
FOLLOWED = ["FFJ2", "MFJ2", "RFJ2", "LFJ2", "FFJ1", "MFJ1", "WRJ0"]


class Recorder:
    """The newest messages and their arrival times, shared with the test thread. `streams`
    names the ones to record (every subscriber adds to the publishers' real-time work: the
    driver's latency topic alone is a message per command)."""

    TOPICS = {
        "glove": ("/adroit_teleop/glove", GloveSensors),
        "commands": ("/adroit/tendon_force_command", TendonForceCommand),
        "latency": ("/adroit/command_latency", CommandLatency),
        "safe": ("/adroit/safe_state", Bool),
        "targets": ("/adroit_teleop/joint_targets", JointState),
        "joints": ("/adroit/joint_states", JointState),
    }

    def __init__(self, streams=tuple(TOPICS)):
        self.lock = threading.Lock()
        for name in self.TOPICS:
            setattr(self, name, [])
        for name in streams:
            topic, kind = self.TOPICS[name]
            rospy.Subscriber(topic, kind, self.on(getattr(self, name)))

    def on(self, store):
        def callback(msg):
            with self.lock:
                store.append((time.monotonic(), msg))
        return callback

    def since(self, store, t0):
        with self.lock:
            return [m for t, m in store if t >= t0]


class Nearest:
    """Position dicts of the joint_states samples nearest to given stamps (the samples in arrival
    order, which is stamp order: a bisection per stamp, not a scan of thousands of samples)."""

    def __init__(self, samples):
        self.samples = samples
        self.stamps = [m.header.stamp.to_sec() for m in samples]

    def at(self, stamp):
        t = stamp.to_sec()
        i = bisect.bisect_left(self.stamps, t)
        k = min((k for k in (i - 1, i) if 0 <= k < len(self.samples)), key=lambda k: abs(self.stamps[k] - t))
        return dict(zip(self.samples[k].name, self.samples[k].position))


class TeleopPipeline(unittest.TestCase):
    def test_glove_moves_the_simulated_hand_safely(self):
        rec = Recorder()
        deadman = rospy.Publisher("/adroit_teleop/deadman", Bool, queue_size=1, latch=True)
        first = rospy.wait_for_message("/adroit_teleop/glove", GloveSensors, timeout=40)
        start = time.monotonic()
        self.assertEqual(len(first.raw), 22)

        # Released: records flow at the emulator's 120 Hz, and nothing is commanded.
        time.sleep(2.0)
        glove = rec.since(rec.glove, start + 0.5)
        rate = len(glove) / 1.5
        self.assertGreater(rate, 110)
        self.assertLess(rate, 130)
        records = [m.record for m in glove]
        self.assertEqual(records, list(range(records[0], records[0] + len(records))), "records lost")
        self.assertEqual(rec.since(rec.commands, start), [])

        # Pressed: commands flow and the fingers follow the glove.
        deadman.publish(Bool(True))
        pressed = time.monotonic()
        time.sleep(7.0)
        commands = rec.since(rec.commands, pressed + 1.0)
        self.assertGreater(len(commands) / 6.0, 110, "commands at less than the glove rate")
        targets = rec.since(rec.targets, pressed + 2.0)
        joints = Nearest(rec.since(rec.joints, pressed + 1.5))
        errors = {j: [] for j in FOLLOWED}
        spans = {j: [] for j in FOLLOWED}
        for target in targets[::10]:
            want = dict(zip(target.name, target.position))
            have = joints.at(target.header.stamp + rospy.Duration(0.1))  # ~ the hand's lag
            for j in FOLLOWED:
                errors[j].append(have[j] - want[j])
                spans[j].append(want[j])
        for j in FOLLOWED:
            rms = (sum(e * e for e in errors[j]) / len(errors[j])) ** 0.5
            swept = max(spans[j]) - min(spans[j])
            self.assertGreater(swept, 0.5, "%s: the glove target hardly moved (%.2f rad)" % (j, swept))
            # Following, not just moving: the error stays well inside the swept range.
            self.assertLess(rms, 0.2 * swept, "%s: rms error %.3f rad over a sweep of %.2f rad" % (j, rms, swept))
        latencies = sorted(m.latency for m in rec.since(rec.latency, pressed + 1.0))
        self.assertGreater(len(latencies), 500)
        self.assertLess(latencies[len(latencies) // 2], 0.010, "median glove-to-physics latency")
        safe = rec.since(rec.safe, pressed)
        self.assertNotIn(True, [m.data for m in safe])

        # Unplugged (the emulator's --unplug-after): the records stop; so do the commands, and the
        # driver's watchdog takes the robot to its safe state.
        unplug = self.wait_for_gap(rec, timeout=UNPLUG_AFTER + 10)
        time.sleep(1.0)
        self.assertEqual(rec.since(rec.commands, unplug + 0.3), [], "commands while the glove is unplugged")
        self.assertIn(True, [m.data for m in rec.since(rec.safe, unplug)])
        # Back: records flow again, but nothing is commanded until the dead-man is pressed again.
        back = self.wait_for_records(rec, after=unplug + 0.5, timeout=UNPLUG_FOR + 10)
        time.sleep(1.5)
        self.assertGreater(len(rec.since(rec.glove, back)), 100, "the glove did not come back")
        self.assertEqual(rec.since(rec.commands, unplug + 0.3), [])
        deadman.publish(Bool(False))
        time.sleep(0.3)
        deadman.publish(Bool(True))
        again = time.monotonic()
        time.sleep(2.0)
        self.assertGreater(len(rec.since(rec.commands, again + 0.5)), 100, "no commands after the new press")
        safe = rec.since(rec.safe, again)
        self.assertTrue(safe and safe[-1].data is False, "the watchdog latch was not released by the press")

        # Motion capture moves the hand's base (thesis 9.2.3); a pose in another frame does not.
        buf = tf2_ros.Buffer()
        tf2_ros.TransformListener(buf)
        start_pose = buf.lookup_transform("world", "forearm", rospy.Time(0), rospy.Duration(10)).transform
        target = rospy.Publisher("/adroit/hand_base/target", PoseStamped, queue_size=1, latch=True)
        wrong = PoseStamped()
        wrong.header.frame_id = "camera"
        wrong.pose.position.z = start_pose.translation.z + 0.3
        wrong.pose.orientation = start_pose.rotation
        target.publish(wrong)
        time.sleep(1.0)
        held = buf.lookup_transform("world", "forearm", rospy.Time(0), rospy.Duration(5)).transform
        self.assertAlmostEqual(held.translation.z, start_pose.translation.z, delta=0.01)
        up = PoseStamped()
        up.header.frame_id = "world"
        up.pose.position.x, up.pose.position.y = start_pose.translation.x, start_pose.translation.y
        up.pose.position.z = start_pose.translation.z + 0.05
        up.pose.orientation = start_pose.rotation
        target.publish(up)
        time.sleep(1.5)
        moved = buf.lookup_transform("world", "forearm", rospy.Time(0), rospy.Duration(5)).transform
        self.assertAlmostEqual(moved.translation.z, start_pose.translation.z + 0.05, delta=0.01)


    @staticmethod
    def wait_for_gap(rec, timeout):
        """Time of the last glove record before a silence of 0.3 s."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with rec.lock:
                last = rec.glove[-1][0] if rec.glove else 0.0
            if last and time.monotonic() - last > 0.3:
                return last
            time.sleep(0.05)
        raise AssertionError("the glove was never unplugged")

    @staticmethod
    def wait_for_records(rec, after, timeout):
        """Arrival time of the first glove record after `after`."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with rec.lock:
                times = [t for t, _ in rec.glove if t > after]
            if times:
                return times[0]
            time.sleep(0.05)
        raise AssertionError("the glove did not come back")


if __name__ == "__main__":
    rospy.init_node("test_teleop")
    rostest.rosrun("adroit_launch", "teleop_pipeline", TeleopPipeline)
