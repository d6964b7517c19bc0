#!/usr/bin/python3
"""Safety of the simulation driver through its ROS interface (hand scene, paused lockstep):
e-stop (pressures to atmosphere within 200 ms, commands ignored while latched, release
refused while the input is held), command watchdog (safe state within one 200 Hz control
period of the timeout), and bad commands (rejected, counted, the node keeps running)."""
import math
import re
import threading
import time
import unittest

import rospy
import rostest
from adroit_msgs.msg import TendonForceCommand, ValveCommand
from diagnostic_msgs.msg import DiagnosticStatus

from driver_client import DriverClient

ATM = 101325.0
N = 40  # hand scene cylinders
CONTROL_PERIOD = 0.005  # 200 Hz


class LockstepSafety(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.d = DriverClient()
        cls.d.pause(True)

    def setUp(self):
        d = self.d
        d.estop_input_pub.publish(False)
        time.sleep(0.1)
        self.assertTrue(d.release().success)
        self.assertTrue(d.reset(keyframe="home").success)

    def pressurise(self, volts, seconds):
        """Runs a 200 Hz controller for `seconds` of simulated time (re-sending every 20 ms)."""
        t_end = self.d.step(1)[0] + seconds
        t = 0
        while t < t_end:
            self.d.command_all(volts, N)
            time.sleep(0.02)
            t, msg = self.d.step(10)
        return msg

    def test_estop_during_a_long_step_is_served_at_once_and_cancels_it(self):
        """A /step of 400 000 steps (800 simulated seconds) is running: the e-stop service
        must answer at once (its own queue and thread), latch the safe state, and stop the
        stepping within one control period of simulated time."""
        d = self.d
        # No command since the release: the watchdog is not armed, so only the e-stop can
        # bring the safe state here.
        self.assertFalse(d.latest_safe_state())
        step_result = {}
        stepper = threading.Thread(target=lambda: step_result.update(r=d.step_srv(steps=400000)))
        stepper.start()
        time.sleep(1.0)  # well into the request
        self.assertTrue(stepper.is_alive(), "precondition: the long step is still running")
        count_before = d.counted("actuator_states")
        t0 = time.time()
        answer = d.estop()
        estop_latency = time.time() - t0
        stepper.join(timeout=5.0)
        self.assertFalse(stepper.is_alive(), "the e-stop did not cancel the running /step")
        print("e-stop answered after %.1f ms during a long /step" % (estop_latency * 1e3))
        self.assertTrue(answer.success)
        self.assertLess(estop_latency, 0.5, "e-stop served only after %.2f s" % estop_latency)
        r = step_result["r"]
        self.assertFalse(r.success)
        self.assertIn("cancelled by /adroit/estop", r.message)
        latched_at = float(re.search(r"at simulated time ([0-9.]+) s", answer.message).group(1))
        self.assertLessEqual(r.sim_time - latched_at, CONTROL_PERIOD + 1e-9,
                             "stepping went on %.4f s (simulated) after the e-stop" % (r.sim_time - latched_at))
        # Every state published after the latch shows every valve open to exhaust.
        after = [m for m in d.messages_since("actuator_states", count_before)
                 if m.header.stamp.to_sec() > latched_at + 1e-9]
        self.assertTrue(all(v == -5.0 for m in after for v in m.command))
        self.assertEqual(d.latest_safe_state(), True)

    def test_step_waits_for_the_command_stamped_for_it(self):
        """A lockstep controller's step names the stamp of its command: the driver steps only
        once that command has arrived (so the period runs on it), and fails clearly when it
        never comes."""
        d = self.d
        t, _ = d.step(1)
        stamp = rospy.Time.from_sec(1000.0 + t)  # newer than any command sent so far
        t0 = time.time()
        r = d.step_srv(steps=1, command_stamp=stamp)
        waited = time.time() - t0
        self.assertFalse(r.success)
        self.assertIn("no valid force or valve command stamped at or after", r.message)
        self.assertGreater(waited, 1.5, "the step did not wait for the command")
        # The step is requested first; the command follows 0.3 s later and is the one applied.
        result = {}
        stepper = threading.Thread(target=lambda: result.update(r=d.step_srv(steps=1, command_stamp=stamp)))
        stepper.start()
        time.sleep(0.3)
        self.assertTrue(stepper.is_alive(), "stepped before its command arrived")
        before = d.counted("actuator_states")
        msg = ValveCommand(index=list(range(N)), volts=[2.5] * N)
        msg.header.stamp = stamp
        d.valve_pub.publish(msg)
        stepper.join(timeout=5.0)
        self.assertTrue(result["r"].success, result["r"].message)
        state = d.wait_new("actuator_states", before, 5.0)
        self.assertTrue(all(abs(v - 2.5) < 1e-12 for v in state.command), "the step ran on another command")

    def test_step_requests_are_bounded(self):
        r = self.d.step_srv(steps=500001)
        self.assertFalse(r.success)
        self.assertIn("at most 500000 steps per request", r.message)

    def test_estop_exhausts_within_200ms_ignores_commands_and_latches(self):
        d = self.d
        d.command_and_confirm(5.0, N)
        msg = self.pressurise(5.0, 0.6)
        self.assertGreater(min(msg.pressure), 400e3, "precondition: cylinders pressurised")
        t_stop, _ = d.step(1)
        self.assertTrue(d.estop().success)
        within = None
        t = t_stop
        while t < t_stop + 0.25:
            t, msg = d.step(1)
            self.assertTrue(all(v == -5.0 for v in msg.command), "every valve open to exhaust")
            if within is None and all(abs(p - ATM) <= 5e3 for p in msg.pressure):
                within = t - t_stop
        self.assertIsNotNone(within, "pressures %s" % [round(p) for p in msg.pressure])
        self.assertLessEqual(within, 0.2 + 1e-9)
        # Commands while latched are ignored (and counted).
        before = int(d.diagnostics()["ignored_while_safe"])
        d.command_all(5.0, N)
        time.sleep(0.1)
        for _ in range(20):
            t, msg = d.step(1)
        self.assertTrue(all(v == -5.0 for v in msg.command))
        self.assertTrue(all(abs(p - ATM) <= 5e3 for p in msg.pressure))
        self.assertGreater(int(d.diagnostics()["ignored_while_safe"]), before)
        self.assertEqual(d.diagnostics()["estop_latched"], "true")

    def test_release_refused_while_estop_input_held(self):
        d = self.d
        d.estop_input_pub.publish(True)
        time.sleep(0.2)
        self.assertEqual(d.diagnostics()["estop_input"], "true")
        res = d.release()
        self.assertFalse(res.success)
        self.assertIn("held", res.message)
        d.estop_input_pub.publish(False)
        time.sleep(0.2)
        self.assertEqual(d.diagnostics()["safe_state"], "true", "latched until released")
        self.assertTrue(d.release().success)
        d.command_and_confirm(1.5, N)

    def test_never_commanded_cylinders_warn_after_the_grace_period(self):
        """The watchdog only watches commanded cylinders: a pool that never started leaves
        its cylinders unwatched, which diagnostics must say (grace 1 s in this test)."""
        d = self.d
        grace = float(rospy.get_param("/adroit_sim/never_commanded_grace"))
        time.sleep(grace + 0.3)  # setUp released: no command since
        level, message, values = d.diagnostics_status()
        self.assertEqual(values["never_commanded"], str(N))
        self.assertEqual(level, DiagnosticStatus.WARN, message)
        self.assertIn("%d cylinders never commanded" % N, message)
        # Half the cylinders commanded (one pool of two running): the other half is named.
        d.valve_pub.publish(ValveCommand(index=list(range(N // 2)), volts=[0.0] * (N // 2)))
        d.step(1)
        level, message, values = d.diagnostics_status()
        self.assertEqual(values["never_commanded"], str(N - N // 2))
        self.assertIn("A_", values["never_commanded_names"])
        self.assertEqual(level, DiagnosticStatus.WARN, message)
        d.command_and_confirm(0.0, N)  # all of them: OK again
        level, message, values = d.diagnostics_status()
        self.assertEqual(values["never_commanded"], "0")
        self.assertEqual(level, DiagnosticStatus.OK, message)

    def test_watchdog_trips_within_one_control_period_after_timeout(self):
        d = self.d
        timeout = float(rospy.get_param("/adroit_sim/watchdog_timeout"))
        # The last command arrives while paused: the driver's clock is frozen at t_cmd.
        t_before = d.step(1)[0]
        d.command_all(2.0, N)
        time.sleep(0.3)
        t_cmd = t_before
        t, msg = d.step(1)
        self.assertTrue(all(v == 2.0 for v in msg.command), "command applied")
        safe_at = None
        while t < t_cmd + timeout + 0.05:
            t, msg = d.step(1)
            if all(v == -5.0 for v in msg.command):
                safe_at = t
                break
            self.assertLess(t - t_cmd, timeout + CONTROL_PERIOD + 1e-9)
        self.assertIsNotNone(safe_at, "watchdog never tripped")
        # msg covers the step that ended at safe_at; the safe command acted during it.
        self.assertGreaterEqual(safe_at - t_cmd, timeout - 1e-9)
        self.assertLessEqual(safe_at - t_cmd, timeout + CONTROL_PERIOD + 1e-9)
        self.assertEqual(d.diagnostics()["watchdog_latched"], "true")

    def test_bad_commands_are_rejected_counted_and_the_node_keeps_running(self):
        d = self.d
        d.command_and_confirm(1.0, N)
        before = d.diagnostics()
        bad = [
            ValveCommand(index=[0, 1], volts=[1.0, float("nan")]),
            ValveCommand(index=[0], volts=[float("inf")]),
            ValveCommand(index=[0, 1, 2], volts=[1.0, 1.0]),
            ValveCommand(name=["A_NOPE_flex"], volts=[1.0]),
            ValveCommand(index=[N], volts=[1.0]),
            ValveCommand(index=[0], volts=[7.5]),
            ValveCommand(name=["A_FFJ3_flex"], index=[0], volts=[1.0]),
        ]
        for msg in bad:
            d.valve_pub.publish(msg)
            time.sleep(0.02)
        force_pub = rospy.Publisher("/adroit/tendon_force_command", TendonForceCommand, queue_size=10)
        time.sleep(0.5)
        force_pub.publish(TendonForceCommand(index=[0], force=[1.0]))  # wrong mode
        time.sleep(0.3)
        after = d.diagnostics()
        delta = lambda k: int(after[k]) - int(before[k])
        self.assertEqual(delta("rejected_not_finite"), 2)
        self.assertEqual(delta("rejected_addressing"), 2)
        self.assertEqual(delta("rejected_name"), 2)
        self.assertEqual(delta("rejected_range"), 1)
        self.assertEqual(delta("rejected_wrong_mode"), 1)
        # Nothing was applied, the driver still runs and takes good commands.
        t, msg = d.step(1)
        self.assertTrue(all(v == 1.0 for v in msg.command))
        self.assertEqual(after["safe_state"], "false")
        d.command_and_confirm(-1.0, N)


if __name__ == "__main__":
    rospy.init_node("test_lockstep_safety")
    rostest.rosrun("adroit_driver", "lockstep_safety", LockstepSafety)
