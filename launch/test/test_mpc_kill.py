#!/usr/bin/python3
"""Killing the behaviour MPC (SIGKILL) during the pneumatic catch leaves the driver up and
safe: its process stays, within the pools' reference timeout (plus a margin for a loaded
machine) every cylinder's applied valve command is at exhaust or the driver is in its safe
state, its services answer, its diagnostics keep coming."""
import os
import signal
import time
import unittest
import xmlrpc.client

import rosgraph
import rospy
import rostest
from adroit_msgs.msg import ActuatorStates, ForceReference, ValveCommand
from adroit_msgs.srv import Reset
from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import Bool
from std_srvs.srv import SetBool, Trigger

EXHAUST = -5.0  # V: adroit_pneumatics/config/pools.yaml exhaust_volts
REFERENCE_TIMEOUT = 0.25  # s: pools.yaml reference_timeout, after which a pool exhausts its cylinders
MARGIN = 0.75  # s: the pools' tick, the driver's publication, and stalls of a loaded 2-core VM


def pid_of(node):
    master = rosgraph.Master("/test_mpc_kill")
    code, _, pid = xmlrpc.client.ServerProxy(master.lookupNode(node)).getPid("/test_mpc_kill")
    assert code == 1, f"no pid for {node}"
    return pid


def alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie has died
        return f.read().rsplit(")", 1)[1].split()[0] != "Z"


class MpcKill(unittest.TestCase):
    def setUp(self):
        self.states = []  # (arrival, ActuatorStates)
        self.safe = None
        self.diagnostics = []  # arrival times of the driver's status
        rospy.Subscriber("/adroit/actuator_states", ActuatorStates,
                         lambda m: self.states.append((time.monotonic(), m)), queue_size=50)
        rospy.Subscriber("/adroit/safe_state", Bool, lambda m: setattr(self, "safe", m.data))
        rospy.Subscriber("/adroit/diagnostics", DiagnosticArray, self.on_diagnostics, queue_size=10)

    def on_diagnostics(self, msg):
        if any(s.name == "adroit_sim" for s in msg.status):
            self.diagnostics.append(time.monotonic())

    def wait_until(self, condition, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if condition():
                return True
            time.sleep(0.005)
        return condition()

    def start_the_catch(self):
        rospy.wait_for_message("/adroit/valve_command", ValveCommand, timeout=60)  # the pools are up
        rospy.wait_for_service("/adroit/pause", timeout=10)
        rospy.ServiceProxy("/adroit/pause", SetBool)(False)
        rospy.wait_for_message("/adroit/force_reference", ForceReference, timeout=60)  # the MPC plans
        # The pools follow its references: some valve leaves exhaust.
        self.assertTrue(self.wait_until(lambda: self.states and max(self.states[-1][1].command) > EXHAUST + 0.5, 10),
                        "the pools never commanded a valve away from exhaust")

    def test_a_dead_mpc_leaves_the_driver_up_and_safe(self):
        self.start_the_catch()
        driver = pid_of("/adroit_sim")
        os.kill(pid_of("/adroit_mpc"), signal.SIGKILL)
        killed = time.monotonic()

        def exhausted():
            fresh = [m for t, m in self.states[-5:] if t > killed]
            return self.safe or (fresh and all(c == EXHAUST for c in fresh[-1].command))

        self.wait_until(lambda: not alive(driver) or exhausted(), REFERENCE_TIMEOUT + MARGIN)
        print("mpc_kill: valves at exhaust (or safe state) %.3f s after the MPC was killed" %
              (time.monotonic() - killed), flush=True)
        self.assertTrue(alive(driver), "the driver died with the MPC")
        self.assertTrue(exhausted(), "valves not at exhaust (and no safe state) %.2f s after the MPC died: %s" %
                        (REFERENCE_TIMEOUT + MARGIN, self.states[-1][1].command if self.states else "no states"))
        time.sleep(1.0)  # roslaunch has seen the death by now (it polls every 0.1 s)
        self.assertTrue(alive(driver), "the driver died with the MPC")
        published = len(self.states)
        time.sleep(0.5)  # 125 states at 250 Hz
        self.assertGreater(len(self.states), published + 20, "the driver stopped publishing")
        self.assertTrue(exhausted(), "a valve left exhaust after the MPC died")

        # The operator's services still answer.
        self.assertTrue(rospy.ServiceProxy("/adroit/estop", Trigger)().success)
        self.assertTrue(self.wait_until(lambda: self.safe, 1.0), "safe_state not true after /adroit/estop")
        rospy.ServiceProxy("/adroit/estop_release", Trigger)()  # answering is what counts here
        self.assertTrue(rospy.ServiceProxy("/adroit/reset", Reset)(keyframe="home").success)
        # And diagnostics keep coming (1 Hz).
        seen = len([t for t in self.diagnostics if t > killed])
        self.assertTrue(self.wait_until(lambda: len([t for t in self.diagnostics if t > killed]) >= seen + 2, 3.5),
                        "no driver diagnostics after the MPC died")
        self.assertTrue(alive(driver), "the driver died")


if __name__ == "__main__":
    rospy.init_node("test_mpc_kill")
    rostest.rosrun("adroit_launch", "mpc_kill", MpcKill)
