"""The probes of behaviour_through_launch.py: each runs one task against a running launch, as a
user does it, and measures the run's window beside it (a rospy node in a process of its own,
stack_run.run_with_launch). Each returns a dict that the caller prints as one JSON line.

  catch     demo_report (as scripts/demo.sh runs it beside demo.launch): it starts the paused
            driver, gives the MPC the bottle, drops it 7 cm above the palm and prints CAUGHT or
            NOT caught after 3 s; the window is from the MPC's first output to that verdict.
  relocate  the ball held at its start for 0.4 s and let go into the hand, the goal given through
            /adroit/mpc/set_task 1 s later, the ball's distance to the goal 3 s after that
            (mpc_success's relocation); the window is from the hold to the end.
  type      typing_through_node.py's probe (its idle period, then the sequence on
            /adroit/mpc/type); the window is from its start-up's end to its result.

The window: the MPC's diagnostics (time_total_ms, policy_age_mean_ms), the CPU per node
(stack_run.StackCpu), the driver's watchdog trips (stack_run.DriverWatch) and machine_slowdown
beside it (adroit_core's machine_probe.MachineProbe)."""
import json
import math
import os
import re
import subprocess
import sys
import time

from stack_run import DriverWatch, StackCpu

HERE = os.path.dirname(os.path.abspath(__file__))
MPC_WAIT_S = 60.0
CATCH_ARGS = ["_drop_height:=0.07", "_watch:=3.0", "_pause_at_end:=true"]  # as scripts/demo.sh
# The ball held still at its start before it is let go, as long as mpc_success's pre-roll in
# pneumatic relocation: the hand is ready when the ball falls. (It was 0.4 s; with
# w_arm_posture 1 the arm idled 0.35 rad below rest without the ball, and the hand was still
# rising into the released ball and threw it off.)
RELOCATE_HOLD_S = 1.5
RELOCATE_GOAL_DELAY_S = 1.0  # mpc_success kRelocateGoalDelay
RELOCATE_GOAL_TIME_S = 3.0   # from the goal to the verdict (mpc_success: 3 s)
RELOCATE_TOLERANCE = 0.03    # m
CATCH_VERDICT = re.compile(r"it is ([0-9.]+) cm from the goal.*lowest height ([-0-9.]+) m.*: (CAUGHT|NOT caught)")


def parse_catch(text):
    """demo_report's verdict: {caught, distance_cm, lowest_m}; caught None when it printed none."""
    found = CATCH_VERDICT.search(text)
    if not found:
        return {"caught": None, "distance_cm": None, "lowest_m": None}
    return {"caught": found.group(3) == "CAUGHT", "distance_cm": float(found.group(1)),
            "lowest_m": float(found.group(2))}


def last_json(text):
    """The last line of `text` that is a JSON object (a probe's result), or None."""
    lines = [line for line in text.splitlines() if line.startswith("{")]
    return json.loads(lines[-1]) if lines else None


class Window:
    """One run's measurements between start() and stop() (stop returns them as a dict). As a
    context manager it starts on entry and is stopped on exit if it is still running, so that
    machine_slowdown (SCHED_FIFO 99) never outlives a probe that failed."""

    def __init__(self, exclude=()):
        import rospkg
        import rospy
        from diagnostic_msgs.msg import DiagnosticArray

        sys.path.insert(0, os.path.join(rospkg.RosPack().get_path("adroit_core"), "tools"))
        self.mpc, self.recording, self.machine, self.t0, self.result = [], False, None, None, None
        self.driver = DriverWatch()
        self.cpu = StackCpu(rospy.get_name(), exclude)
        rospy.Subscriber("/adroit/diagnostics", DiagnosticArray, self._on_diagnostics, queue_size=20)

    def _on_diagnostics(self, msg):
        for s in msg.status:
            if s.name == "adroit_mpc" and self.recording:
                v = {kv.key: kv.value for kv in s.values}
                self.mpc.append((float(v.get("time_total_ms", "nan")), float(v.get("policy_age_mean_ms", "nan"))))

    def start(self):
        from machine_probe import MachineProbe

        self.machine = MachineProbe()
        try:
            self.cpu.start()
        except Exception:
            self.machine.stop()
            raise
        self.driver.start()
        self.recording, self.t0 = True, time.monotonic()

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop()
        return False

    def stop(self):
        if self.result is not None:
            return self.result
        self.recording = False
        seconds = time.monotonic() - self.t0
        try:
            cores = self.cpu.stop()
        finally:
            fraction, summary = self.machine.stop()
        self.result = {"window_s": seconds, "cores": cores, "watchdog_trips": self.driver.stop(),
                       "load_average": os.getloadavg()[0],
                       "safe_state": self.driver.in_safe_state(), "slowdown_fraction": fraction,
                       "stall_ms": self.machine.stall_ms, "slowdown_summary": summary,
                       "iteration_ms": [a for a, _ in self.mpc if a > 0],
                       "policy_age_ms": [b for _, b in self.mpc if b > 0]}
        return self.result


def wait_for_mpc(mode, timeout=MPC_WAIT_S):
    """Until the behaviour MPC's first output: force references to the pools, or tendon forces."""
    import rospy
    from adroit_msgs.msg import ForceReference, TendonForceCommand

    if mode == "pneumatic":
        rospy.wait_for_message("/adroit/force_reference", ForceReference, timeout=timeout)
    else:
        rospy.wait_for_message("/adroit/tendon_force_command", TendonForceCommand, timeout=timeout)


def probe_catch(p):
    import rospy

    window = Window(exclude=("demo_report",))
    report = subprocess.Popen(["rosrun", "adroit_launch", "demo_report.py"] + CATCH_ARGS,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        wait_for_mpc(p["mode"])  # demo_report starts the paused driver once the pools command
    except rospy.ROSException:
        report.kill()
        return {"error": "the behaviour MPC published nothing: " + report.communicate()[0][-500:]}
    lines = []
    with window:
        for line in report.stdout:  # the verdict closes the window (the report pauses the driver after it)
            lines.append(line)
            if "CAUGHT" in line or "NOT caught" in line:
                break
    result = dict(window.result)
    rest, _ = report.communicate(timeout=60)
    text = "".join(lines) + rest
    result.update(parse_catch(text))
    result.update({"success": bool(result["caught"]), "sound": report.returncode == 0})
    if result["caught"] is None:
        result["error"] = "demo_report gave no verdict: " + text[-500:]
    return result


def pose_at(xyz):
    from geometry_msgs.msg import Pose

    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = xyz
    pose.orientation.w = 1.0
    return pose


def probe_relocate(p):
    import rospy
    from adroit_msgs.srv import SetObjectPose, SetObjectPoseRequest, SetTask, SetTaskRequest
    from nav_msgs.msg import Odometry

    window = Window()
    ball = {"position": None, "lowest": None}

    def on_odom(msg):
        q = msg.pose.pose.position
        ball["position"] = (q.x, q.y, q.z)
        if ball["lowest"] is not None:
            ball["lowest"] = min(ball["lowest"], q.z)

    rospy.Subscriber("/adroit/object/odom", Odometry, on_odom, queue_size=10)
    try:
        wait_for_mpc(p["mode"])
        rospy.wait_for_service("/adroit/set_object_pose", timeout=10)
        rospy.wait_for_service("/adroit/mpc/set_task", timeout=10)
    except rospy.ROSException as e:
        return {"error": "the stack did not come up: %s" % e}
    place = rospy.ServiceProxy("/adroit/set_object_pose", SetObjectPose)
    set_task = rospy.ServiceProxy("/adroit/mpc/set_task", SetTask)
    hold = rospy.get_param("/adroit_mpc/tasks/relocate/hold_position")  # the draws are relative to it
    start_xyz, goal_xyz = [[h + d for h, d in zip(hold, p[k])] for k in ("start", "goal")]
    start, goal_pose = pose_at(start_xyz), pose_at(goal_xyz)

    with window:
        hold_until = time.monotonic() + RELOCATE_HOLD_S
        while time.monotonic() < hold_until:  # held still above the hand, as a person's hand would
            place(SetObjectPoseRequest(pose=start))
            time.sleep(0.01)
        placed = place(SetObjectPoseRequest(pose=start))  # let go
        ball["lowest"] = start_xyz[2]
        time.sleep(RELOCATE_GOAL_DELAY_S)
        at_goal_time = ball["position"]  # the ball still held? (the catch that relocation starts with)
        goal = set_task(SetTaskRequest(task="relocate", goal=goal_pose))
        time.sleep(RELOCATE_GOAL_TIME_S)
        end = ball["position"]
    result = dict(window.result)
    distance = math.dist(end, goal_xyz) if end else float("inf")
    result.update({"distance_cm": 100 * distance, "lowest_m": ball["lowest"], "end": end, "goal": goal_xyz,
                   "from_hold_cm": 100 * math.dist(at_goal_time, hold) if at_goal_time else None,
                   "success": bool(placed.success and goal.success and distance <= RELOCATE_TOLERANCE)})
    if not (placed.success and goal.success):
        result["error"] = "refused: " + (placed.message if not placed.success else goal.message)
    return result


def probe_type(p):
    import typing_through_node

    window = Window(exclude=("typing_probe",))
    typing = subprocess.Popen([sys.executable, os.path.join(HERE, "typing_through_node.py"), "--probe",
                               str(p["idle"]), p["sequence"]], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True)
    time.sleep(typing_through_node.STARTUP_S)  # its start-up; then its idle period and the sequence
    with window:
        try:
            out, err = typing.communicate(timeout=p["idle"] + typing_through_node.PER_KEY_S * len(p["sequence"]) + 60)
        except subprocess.TimeoutExpired:
            typing.kill()
            out, err = typing.communicate()
            err = "timed out; " + err
    result = dict(window.result)
    typed = last_json(out)
    if typed is None or not typed.get("sequences"):
        result.update({"success": False, "error": "the typing probe gave no result: " + err[-500:]})
        return result
    s = typed["sequences"][0]
    result.update({"typed": s["typed"], "keys_right": s["right"], "keys": len(s["sequence"]),
                   "presses": s.get("presses"), "wrong_presses": s.get("wrong"), "unasked": len(typed["unasked"]),
                   "events": s.get("events", []), "unasked_keys": typed["unasked"],
                   "success": s["right"] == len(s["sequence"]) and not typed["unasked"]})
    return result


def probe(task, params):
    """Child process: runs the task once against the launch; prints one JSON line."""
    import rospy

    rospy.init_node("behaviour_probe", anonymous=True, disable_signals=True)
    result = {"catch": probe_catch, "relocate": probe_relocate, "type": probe_type}[task](params)
    print(json.dumps(result), flush=True)
