"""Runs a roslaunch of the stack on a master of its own (a random port) and a probe beside it:
the probe is this same program run again with --probe (rospy can join one master per process),
which prints its result as the last JSON line. For the benchmarks of the whole stack through
roslaunch (command_margin.py, typing_through_node.py)."""
import json
import os
import random
import signal
import subprocess
import sys
import time


def run_with_launch(launch_args, probe_args, timeout, log):
    """roslaunch -p <port> <launch_args...>, then `python3 <main program> --probe <probe_args...>`
    against it; returns the probe's JSON result. The launch is stopped with SIGINT (as Ctrl-C)."""
    port = random.randint(20000, 40000)
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port)
    launch = subprocess.Popen(["roslaunch", "-p", str(port)] + list(launch_args), env=env, stdout=log,
                              stderr=subprocess.STDOUT, start_new_session=True)
    try:
        for _ in range(150):  # the master is up
            if subprocess.run(["rosparam", "get", "/rosversion"], env=env, capture_output=True).returncode == 0:
                break
            time.sleep(0.2)
        out = subprocess.run([sys.executable, os.path.abspath(sys.argv[0]), "--probe"] + [str(a) for a in probe_args],
                             env=env, capture_output=True, text=True, timeout=timeout)
        lines = [l for l in out.stdout.splitlines() if l.startswith("{")]
        if not lines:
            raise RuntimeError("the probe gave no result: " + out.stderr[-2000:])
        return json.loads(lines[-1])
    finally:
        os.killpg(launch.pid, signal.SIGINT)
        try:
            launch.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(launch.pid, signal.SIGKILL)


def percentile(values, q):
    s = sorted(values)
    return s[min(len(s) - 1, int(q * len(s)))] if s else float("nan")


class DriverWatch:
    """In a probe: the simulation driver's diagnostics (/adroit/diagnostics, status adroit_sim).
    Between start() and stop() each report's values are kept (one a second); release_trip()
    releases a latched watchdog trip at once, so that each trip counts. stop() returns the trips
    since start()."""

    def __init__(self):
        import rospy
        from diagnostic_msgs.msg import DiagnosticArray
        from std_srvs.srv import Trigger
        self.latest, self.samples, self.recording, self._trips_before = {}, [], False, 0
        rospy.Subscriber("/adroit/diagnostics", DiagnosticArray, self._on_diagnostics, queue_size=20)
        self._release = rospy.ServiceProxy("/adroit/estop_release", Trigger)

    def _on_diagnostics(self, msg):
        for s in msg.status:
            if s.name == "adroit_sim":
                values = {kv.key: kv.value for kv in s.values}
                self.latest.update(values)
                if self.recording:
                    self.samples.append(values)

    def _trips(self):
        return int(self.latest.get("watchdog_trips", "0"))

    def start(self):
        self._trips_before = self._trips()
        self.recording = True

    def stop(self):
        self.recording = False
        return self._trips() - self._trips_before

    def in_safe_state(self):
        return self.latest.get("safe_state") == "true"

    def release(self):
        self._release()

    def release_trip(self):
        if self.in_safe_state() and self.latest.get("watchdog_latched") == "true":
            self.release()
