"""Small client of the simulation driver for the rostests: latest messages, stepping a
paused simulation, commands, diagnostics."""
import collections
import threading
import time

import rospy
from adroit_msgs.msg import ActuatorStates, ValveCommand
from adroit_msgs.srv import Reset, SetObjectPose, Step
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool
from std_srvs.srv import SetBool, Trigger


HISTORY = 20000


class DriverClient:
    def __init__(self, object_odom=False):
        self.lock = threading.Lock()
        self.latest, self.count, self.clocks, self.stamps = {}, {}, [], {}
        self.history = {}  # topic -> deque of (count, message), the newest HISTORY
        self.safe_state = None
        topics = [("joint_states", JointState), ("actuator_states", ActuatorStates), ("diagnostics", DiagnosticArray)]
        if object_odom:
            topics.append(("object/odom", Odometry))
        self.subs = [rospy.Subscriber("/adroit/" + t, c, self._store, t, queue_size=100) for t, c in topics]
        self.subs.append(rospy.Subscriber("/clock", Clock, self._clock, queue_size=1000))
        self.subs.append(rospy.Subscriber("/adroit/safe_state", Bool, self._safe_state, queue_size=10))
        self.valve_pub = rospy.Publisher("/adroit/valve_command", ValveCommand, queue_size=10)
        self.estop_input_pub = rospy.Publisher("/adroit/estop_input", Bool, queue_size=1, latch=True)
        for s in ("reset", "step", "pause", "estop", "estop_release", "set_object_pose"):
            rospy.wait_for_service("/adroit/" + s, timeout=60)
        self.reset = rospy.ServiceProxy("/adroit/reset", Reset)
        self.step_srv = rospy.ServiceProxy("/adroit/step", Step)
        self.pause = rospy.ServiceProxy("/adroit/pause", SetBool)
        self.estop = rospy.ServiceProxy("/adroit/estop", Trigger)
        self.release = rospy.ServiceProxy("/adroit/estop_release", Trigger)
        self.set_object_pose = rospy.ServiceProxy("/adroit/set_object_pose", SetObjectPose)
        deadline = time.time() + 10
        while self.valve_pub.get_num_connections() == 0 and time.time() < deadline:
            time.sleep(0.05)

    def _store(self, msg, topic):
        with self.lock:
            self.latest[topic] = msg
            self.count[topic] = self.count.get(topic, 0) + 1
            self.history.setdefault(topic, collections.deque(maxlen=HISTORY)).append((self.count[topic], msg))
            if hasattr(msg, "header") and topic != "diagnostics":
                self.stamps.setdefault(topic, []).append(msg.header.stamp.to_sec())

    def _clock(self, msg):
        with self.lock:
            self.clocks.append(msg.clock.to_sec())

    def _safe_state(self, msg):
        with self.lock:
            self.safe_state = msg.data

    def latest_safe_state(self, timeout=2.0):
        """The latched /adroit/safe_state, after `timeout` s for a change to arrive."""
        time.sleep(timeout)
        with self.lock:
            return self.safe_state

    def messages_since(self, topic, after_count):
        """Messages of `topic` received after the first `after_count` (the newest HISTORY)."""
        with self.lock:
            return [m for c, m in self.history.get(topic, ()) if c > after_count]

    def counted(self, topic):
        with self.lock:
            return self.count.get(topic, 0)

    def wait_new(self, topic, after_count, timeout=10.0):
        """The first message of `topic` received after `after_count` messages."""
        deadline = time.time() + timeout
        while time.time() < deadline:
            with self.lock:
                if self.count.get(topic, 0) > after_count:
                    return self.latest[topic]
            time.sleep(0.002)
        raise AssertionError("no new message on %s within %.0f s" % (topic, timeout))

    def step(self, steps=1, topic="actuator_states"):
        """Steps a paused simulation; returns (sim time, latest `topic` message after it)."""
        before = self.counted(topic)
        res = self.step_srv(steps=steps)
        assert res.success, res.message
        deadline = time.time() + 10
        while time.time() < deadline:
            with self.lock:
                msg = self.latest.get(topic)
                if msg is not None and abs(msg.header.stamp.to_sec() - res.sim_time) < 1e-6 and self.count[topic] > before:
                    return res.sim_time, msg
            time.sleep(0.001)
        raise AssertionError("no %s stamped %.4f after stepping" % (topic, res.sim_time))

    def command_all(self, volts, n):
        self.valve_pub.publish(ValveCommand(index=list(range(n)), volts=[volts] * n))

    def command_and_confirm(self, volts, n):
        """Publishes a command while paused and steps once until the driver applies it."""
        for _ in range(50):
            self.command_all(volts, n)
            time.sleep(0.05)
            t, msg = self.step(1)
            if all(abs(v - volts) < 1e-12 for v in msg.command):
                return t
        raise AssertionError("command %.2f V never applied" % volts)

    def diagnostics(self, timeout=5.0):
        return self.diagnostics_status(timeout)[2]

    def diagnostics_status(self, timeout=5.0):
        """(level, message, key -> value) of the driver's next diagnostics."""
        msg = self.wait_new("diagnostics", self.counted("diagnostics"), timeout)
        status = msg.status[0]
        return status.level, status.message, {kv.key: kv.value for kv in status.values}
