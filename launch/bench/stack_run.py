"""Runs a roslaunch of the stack on a master of its own (a random port) and a probe beside it:
the probe is this same program run again with --probe (rospy can join one master per process),
which prints its result as the last JSON line. For the benchmarks of the whole stack through
roslaunch (command_margin.py, typing_through_node.py, stack_cpu.py, behaviour_through_launch.py).
In a probe, StackCpu measures the CPU each node of the launch used over a window."""
import json
import os
import random
import signal
import subprocess
import sys
import time

CLK_TCK = os.sysconf("SC_CLK_TCK")


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


def thread_times(pids):
    """{(node, tid): (cpu seconds, class)} for every thread of the given {node: pid}; the class is
    fifo (SCHED_FIFO or SCHED_RR: command paths), niced (nice > 0: the MPC's optimiser) or normal."""
    out = {}
    for node, pid in pids.items():
        try:
            tids = os.listdir("/proc/%d/task" % pid)
        except OSError:
            continue
        for tid in tids:
            try:
                with open("/proc/%d/task/%s/stat" % (pid, tid)) as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            # fields[0] is stat's 3rd field: utime 14, stime 15, nice 19, policy 41.
            cpu = (int(fields[11]) + int(fields[12])) / CLK_TCK
            nice, policy = int(fields[16]), int(fields[38])
            cls = "fifo" if policy in (1, 2) else ("niced" if nice > 0 else "normal")
            out[(node, tid)] = (cpu, cls)
    return out


def node_pids(caller, exclude=()):
    """In a probe: {node: pid} of every node registered with the master (names without the
    leading '/'), the master as 'rosmaster'; /rosout, the caller and the nodes whose name starts
    with one of `exclude` (the probe's helpers) left out."""
    import xmlrpc.client

    import rosgraph
    import rosnode

    master = rosgraph.Master(caller)
    pids = {}
    for name in rosnode.get_node_names():
        if name in (caller, "/rosout") or any(name.lstrip("/").startswith(e) for e in exclude):
            continue
        try:
            code, _, pid = xmlrpc.client.ServerProxy(master.lookupNode(name)).getPid(caller)
        except Exception:  # a node that went away or has no XML-RPC server
            continue
        if code == 1:
            pids[name.lstrip("/")] = pid
    pids["rosmaster"] = master.getPid()
    return pids


def cores_per_node(pids, start, end, seconds):
    """{node: {class: cores}} from two thread_times readings `seconds` apart. A nodelet's loader is
    a node of its own but a process of the manager's: a pid counts once, under its first name."""
    by_pid = {}
    for node, pid in sorted(pids.items()):
        by_pid.setdefault(pid, node)
    cores = {}
    for key, (cpu, cls) in end.items():
        node = by_pid.get(pids[key[0]])
        if node != key[0]:
            continue
        used = (cpu - start.get(key, (cpu, cls))[0]) / seconds
        cores.setdefault(node, {}).setdefault(cls, 0.0)
        cores[node][cls] += used
    return cores


class StackCpu:
    """In a probe: the CPU each node of the launch used over a window. start() finds the nodes'
    processes through the master (getPid) and reads their threads' CPU times from /proc; stop()
    returns {node: {class: cores}} over the window (class as thread_times)."""

    def __init__(self, caller, exclude=()):
        self.caller, self.exclude = caller, tuple(exclude)
        self.pids, self._start, self._t0 = {}, {}, None

    def start(self):
        self.pids = node_pids(self.caller, self.exclude)
        self._start = thread_times(self.pids)
        self._t0 = time.monotonic()

    def stop(self):
        seconds = time.monotonic() - self._t0
        return cores_per_node(self.pids, self._start, thread_times(self.pids), seconds)
