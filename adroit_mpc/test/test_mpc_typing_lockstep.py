#!/usr/bin/env python3
"""Typing through the MPC node in lockstep (mpc_typing_lockstep.test): nothing is typed before
a sequence is given, then its keys are registered in order (a wrong key is corrected with
backspace, as the task does) and the sequence is reported done, within a bounded wall time."""
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import String


class MpcTypingLockstepTest(unittest.TestCase):
    def test_types_the_sequence(self):
        rospy.init_node("test_mpc_typing_lockstep")
        sequence = str(rospy.get_param("~sequence"))
        wall_timeout = float(rospy.get_param("~wall_timeout", 120.0))
        lock = threading.Lock()
        typed, events = [], []

        def on_typed(msg):
            with lock:
                typed.append(msg.data)

        def on_event(msg):
            with lock:
                events.append(msg.data)

        compensated = []  # latency_compensated_ms of the node's diagnostics

        def on_diagnostics(msg):
            for status in msg.status:
                values = {kv.key: kv.value for kv in status.values}
                if status.name == "adroit_mpc" and "latency_compensated_ms" in values:
                    with lock:
                        compensated.append(float(values["latency_compensated_ms"]))

        rospy.Subscriber("/adroit/diagnostics", DiagnosticArray, on_diagnostics, queue_size=50)
        rospy.Subscriber("/adroit/mpc/typed", String, on_typed, queue_size=100)
        rospy.Subscriber("/adroit/mpc/events", String, on_event, queue_size=100)
        pub = rospy.Publisher("/adroit/mpc/type", String, queue_size=1, latch=True)
        # The node plans and steps the driver from the start: 2 simulated seconds with no
        # sequence must type nothing (the hand rests over the keys).
        start = rospy.get_time()
        deadline = time.time() + wall_timeout
        while rospy.get_time() < start + 2.0 and time.time() < deadline:
            time.sleep(0.05)
        self.assertGreaterEqual(rospy.get_time(), start + 2.0, "the lockstep clock did not advance")
        with lock:
            self.assertEqual(typed, [], "keys registered before any sequence was given")
        pub.publish(String(data=sequence))
        done = None
        while time.time() < deadline and done is None:
            with lock:
                done = next((e for e in events if e.startswith("done")), None)
            time.sleep(0.1)
        with lock:
            got, log = list(typed), list(events)
        self.assertIsNotNone(done, "sequence %s not done in %.0f s of wall time; typed %s, events %s"
                             % (sequence, wall_timeout, got, log[-10:]))
        # Replay the corrections: each backspace removes the key before it (enter is a key
        # like the digits: pressed by mistake, it is taken back too).
        text = []
        for key in got:
            if key == "bs":
                if text:
                    text.pop()
            else:
                text.append(key)
        self.assertEqual(text, list(sequence), "typed %s" % got)
        # Typing compensates its planning latency (config/tasks/type.yaml), but in lockstep the
        # world waits for the plan: every plan starts from the measured state, none in a future
        # that never comes.
        with lock:
            self.assertTrue(compensated, "no latency_compensated_ms in the node's diagnostics")
            self.assertEqual(max(compensated), 0.0, compensated)


if __name__ == "__main__":
    rostest.rosrun("adroit_mpc", "mpc_typing_lockstep", MpcTypingLockstepTest)
