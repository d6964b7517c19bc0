#!/usr/bin/python3
"""Demo motion source: a slow open/close wave of the fingers and thumb expressed as tendon
forces, so the sim bringup has something to do before the behaviour MPC exists.

force mode:     publishes /adroit/tendon_force_command at 200 Hz (the driver's ideal actuators)
pneumatic mode: publishes /adroit/force_reference at 20 Hz, a 0.5 s preview at 5 ms steps,
                which the pneumatic pools track with their pressure controllers

Cylinder names come from the driver's /adroit/actuator_states, so nothing is hard-coded but
the naming convention A_<joint>_flex|ext. Arm and wrist cylinders get a balanced co-contraction.
"""
import math

import rospy
from adroit_msgs.msg import ActuatorStates, ForceReference, TendonForceCommand


def desired_force(name, t, period):
    """Tension [N] of one cylinder at time t: flexors and extensors in antiphase."""
    joint, role = name[2:].rsplit("_", 1)
    if joint.startswith("AR") or joint.startswith("WR"):
        return 8.0  # hold posture with a light co-contraction
    finger_phase = {"FF": 0.0, "MF": 0.4, "RF": 0.8, "LF": 1.2, "TH": 1.6}.get(joint[:2], 0.0)
    s = 0.5 * (1.0 - math.cos(2.0 * math.pi * t / period - finger_phase))  # 0..1
    if joint.endswith("J3") or joint == "THJ4":
        s = 0.5  # ab/adduction and thumb rotation: stay centred
    high, low = 12.0, 1.0
    return low + (high - low) * (s if role == "flex" else 1.0 - s)


class DemoMotion:
    def __init__(self):
        self.mode = rospy.get_param("~mode", "pneumatic")
        if self.mode not in ("pneumatic", "force"):
            rospy.logfatal("demo_motion: parameter ~mode must be 'pneumatic' or 'force', got '%s'", self.mode)
            raise SystemExit(2)
        self.period = float(rospy.get_param("~period", 3.0))
        self.names = None
        rospy.Subscriber("/adroit/actuator_states", ActuatorStates, self.on_states, queue_size=1)
        if self.mode == "force":
            self.pub = rospy.Publisher("/adroit/tendon_force_command", TendonForceCommand, queue_size=1)
            self.timer = rospy.Timer(rospy.Duration(0.005), self.publish_force)
        else:
            self.pub = rospy.Publisher("/adroit/force_reference", ForceReference, queue_size=1)
            self.timer = rospy.Timer(rospy.Duration(0.05), self.publish_reference)
        self.start = None

    def on_states(self, msg):
        if self.names is None and msg.name:
            self.names = list(msg.name)
            rospy.loginfo("demo_motion: driving %d cylinders (%s mode)", len(self.names), self.mode)

    def elapsed(self, now):
        if self.start is None:
            self.start = now
        return (now - self.start).to_sec()

    def publish_force(self, _event):
        if self.names is None:
            return
        now = rospy.Time.now()
        t = self.elapsed(now)
        msg = TendonForceCommand()
        msg.header.stamp = now
        msg.name = self.names
        msg.force = [desired_force(n, t, self.period) for n in self.names]
        self.send(msg)

    def send(self, msg):
        try:
            self.pub.publish(msg)
        except rospy.ROSException:
            # A timer tick racing the shutdown is not an error: the topic closes as soon as the
            # shutdown is requested, before is_shutdown() turns true.
            if not (rospy.is_shutdown() or rospy.core.is_shutdown_requested()):
                raise

    def publish_reference(self, _event):
        if self.names is None:
            return
        now = rospy.Time.now()
        t0 = self.elapsed(now)
        msg = ForceReference()
        msg.header.stamp = now
        msg.dt = 0.005
        msg.steps = 100
        msg.name = self.names
        msg.force = [desired_force(n, t0 + k * msg.dt, self.period) for k in range(msg.steps) for n in self.names]
        self.send(msg)


if __name__ == "__main__":
    rospy.init_node("demo_motion")
    DemoMotion()
    rospy.spin()
