#!/usr/bin/python3
"""Real-time mode: every inter-message interval of joint_states (2 ms) and actuator_states
(4 ms) is within 5 % of nominal (by header stamp: no drops, no doubles, no beat), arrival
rates are within 5 % over 10 s of wall time, and the real-time factor is 1.00 +/- 0.05."""
import os
import sys
import threading
import time
import unittest

import rospkg
import rospy
import rostest
from adroit_msgs.msg import ActuatorStates
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState

sys.path.insert(0, os.path.join(rospkg.RosPack().get_path("adroit_core"), "tools"))
from machine_probe import MachineProbe, mark_probe_skips, unless_the_machine_slowed  # noqa: E402


class Stream:
    def __init__(self, topic, cls):
        self.lock = threading.Lock()
        self.stamps, self.arrivals = [], []
        self.recording = False
        self.sub = rospy.Subscriber(topic, cls, self.callback, queue_size=2000, tcp_nodelay=True)

    def callback(self, msg):
        now = time.monotonic()
        with self.lock:
            if self.recording:
                self.stamps.append(msg.header.stamp.to_sec())
                self.arrivals.append(now)


class RealTime(unittest.TestCase):
    def test_rates_intervals_and_rtf(self):
        joints = Stream("/adroit/joint_states", JointState)
        actuators = Stream("/adroit/actuator_states", ActuatorStates)
        resyncs = []  # the driver's count of real-time schedule restarts, from diagnostics
        rospy.Subscriber("/adroit/diagnostics", DiagnosticArray, lambda m: resyncs.extend(
            int(kv.value) for st in m.status if st.name == "adroit_sim" for kv in st.values
            if kv.key == "schedule_resyncs"))
        rospy.wait_for_message("/adroit/joint_states", JointState, timeout=30)
        time.sleep(1.5)
        resyncs_before = resyncs[-1]
        probe = MachineProbe()  # the rates are real time, beside the machine's own speed
        for s in (joints, actuators):
            s.recording = True
        time.sleep(10.0)
        for s in (joints, actuators):
            s.recording = False
        probe.stop()
        time.sleep(1.5)
        with unless_the_machine_slowed(self, probe):
            self.check_window(joints, actuators, resyncs[-1] - resyncs_before)

    def check_window(self, joints, actuators, restarts):
        # On this non-real-time kernel the driver may fall behind (a VM pause); it then
        # restarts its schedule, counts it, and that one stamp interval is irregular. Each
        # irregular interval must be such a counted restart, and they must stay rare.
        self.assertLessEqual(restarts, 2, "the schedule restarted %d times in 10 s" % restarts)
        for name, stream, period in (("joint_states", joints, 0.002), ("actuator_states", actuators, 0.004)):
            stamps, arrivals = stream.stamps, stream.arrivals
            self.assertGreater(len(stamps), 100, name)
            bad = [b - a for a, b in zip(stamps, stamps[1:]) if abs((b - a) - period) > 0.05 * period]
            self.assertLessEqual(len(bad), restarts, "%s: %d stamp intervals outside nominal +/- 5 %%, e.g. %s, "
                                 "with %d schedule restarts" % (name, len(bad), bad[:5], restarts))
            wall = arrivals[-1] - arrivals[0]
            rate = (len(arrivals) - 1) / wall
            self.assertAlmostEqual(rate, 1.0 / period, delta=0.05 / period, msg="%s arrival rate %.1f Hz" % (name, rate))
            rtf = (stamps[-1] - stamps[0]) / wall
            self.assertAlmostEqual(rtf, 1.0, delta=0.05, msg="%s: real-time factor %.4f" % (name, rtf))
            print("%s: %d messages, %.2f Hz, RTF %.4f" % (name, len(stamps), rate, rtf))

    def test_driver_reports_rtf_in_diagnostics(self):
        values = {}
        deadline = time.time() + 15
        while time.time() < deadline:
            msg = rospy.wait_for_message("/adroit/diagnostics", DiagnosticArray, timeout=10)
            values = {kv.key: kv.value for kv in msg.status[0].values}
            if float(values["real_time_factor"]) > 0:
                break
        self.assertAlmostEqual(float(values["real_time_factor"]), 1.0, delta=0.05, msg=str(values))
        self.assertEqual(values["time_mode"], "realtime")
        if os.geteuid() == 0:
            # The physics below the controllers' command paths, the I/O above them (sim.yaml).
            self.assertEqual(values["thread_scheduling"], "SCHED_FIFO 9", str(values))
            self.assertEqual(values["publisher_scheduling"], "SCHED_FIFO 19", str(values))
            self.assertEqual(values["safety_scheduling"], "SCHED_FIFO 18", str(values))
            self.assertEqual(values["transport_scheduling"], "SCHED_FIFO 17", str(values))


if __name__ == "__main__":
    rospy.init_node("test_realtime")
    rostest.rosrun("adroit_driver", "realtime", RealTime)
    mark_probe_skips()
