#!/usr/bin/python3
"""adroit_characterise on the simulation driver: a quick run writes its report, CSVs and plots with
physically plausible, consistent figures; the tool refuses (non-zero exit, one line) while another
node publishes valve commands and while the driver is e-stopped. The cases run in name order."""
import csv
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
import unittest

import rospkg
import rospy
import rostest
from adroit_msgs.msg import ValveCommand
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

sys.path.insert(0, os.path.join(rospkg.RosPack().get_path("adroit_core"), "tools"))
from machine_probe import MachineProbe, mark_probe_skips, unless_the_machine_slowed  # noqa: E402

EXPERIMENTS = ("bang_bang", "limit_to_limit", "reflex", "step", "chirp", "force")


def run_tool(name, output_dir, *params, timeout=100):
    cmd = ["rosrun", "adroit_driver", "adroit_characterise", "__name:=" + name,
           "_output_dir:=" + output_dir] + list(params)
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=timeout, text=True)
    return proc.returncode, proc.stdout + proc.stderr


def table(directory, name):
    with open(os.path.join(directory, name)) as f:
        return list(csv.DictReader(f))


def num(x):
    return float(x) if x not in ("", None) else float("nan")


class Characterise(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_characterise", anonymous=True)
        cls.dir = tempfile.mkdtemp(prefix="characterise_")
        rospy.wait_for_service("/adroit/estop", timeout=60)
        rospy.wait_for_message("/adroit/safe_state", Bool, timeout=60)
        cls.estop = rospy.ServiceProxy("/adroit/estop", Trigger)
        cls.release = rospy.ServiceProxy("/adroit/estop_release", Trigger)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.dir, ignore_errors=True)

    def test_1_quick_run(self):
        # The directory is a parameter: a shell would run what its quotes smuggle in.
        injected = os.path.join(self.dir, "INJECTED")
        out = os.path.join(self.dir, "quick'; touch %s; echo '$(touch %s)" % (injected, injected))
        probe = MachineProbe()  # the figures are measured in real time, beside the machine's own speed
        code, log = run_tool("characterise_quick", out, "_quick:=true")
        probe.stop()
        self.assertEqual(code, 0, log)
        self.assertFalse(os.path.exists(injected), "a shell ran a command from ~output_dir")
        for name in ["report.md", "summary.csv"] + ["%s%s.csv" % (e, s) for e in EXPERIMENTS
                                                   for s in ("", "_joints", "_actuators", "_commands")]:
            self.assertTrue(os.path.getsize(os.path.join(out, name)) > 0, name)
        for png in ("bang_bang", "limit_to_limit", "reflex", "step", "chirp"):
            self.assertTrue(os.path.exists(os.path.join(out, png + ".png")), png)
        report = open(os.path.join(out, "report.md")).read()
        for thesis in ("about 7 Hz", "2.44 s for 24 joints", "8 ms", "29 ms", "about 25 Hz", "300.5 g", "439.4 g"):
            self.assertIn(thesis, report)
        self.assertNotIn("Aborted", report)
        with unless_the_machine_slowed(self, probe):
            self.check_figures(out)

    def check_figures(self, out):
        # Bang-bang: the stroke falls with frequency (over the sweep; noise allowed step to step).
        strokes = table(out, "bang_bang.csv")
        self.assertGreaterEqual(len(strokes), 3)
        amplitude = [num(r["stroke_rad"]) for r in strokes]
        for a, b in zip(amplitude, amplitude[1:]):
            self.assertLessEqual(b, a * 1.05 + 0.02, amplitude)
        self.assertLess(amplitude[-1], 0.5 * amplitude[0], amplitude)
        self.assertGreater(num(strokes[0]["reference_range_rad"]), 0.5)

        # Limit to limit: a positive time for both movements of every joint tested.
        moves = table(out, "limit_to_limit.csv")
        self.assertEqual(len(moves), 8)
        for m in moves:
            t = num(m["time_s"])
            self.assertTrue(0 < t < 1.0, m)

        # Reflex: latencies positive, motion after the first pressure change, both below 0.2 s.
        trials = [t for t in table(out, "reflex.csv") if t["valid"] == "1"]
        self.assertGreaterEqual(len(trials), 1, table(out, "reflex.csv"))
        for t in trials:
            p, m = num(t["pressure_latency_s"]), num(t["motion_latency_s"])
            self.assertTrue(0 < p < m < 0.2, t)

        # Valve steps: towards the supply and back to the atmosphere, finite positive time constants.
        steps = table(out, "step.csv")
        for s in steps:
            self.assertTrue(0 < num(s["time_constant_s"]) < 0.2, s)
            self.assertTrue(0 <= num(s["dead_time_s"]) < 0.05, s)
        up = [s for s in steps if num(s["to_v"]) > 0][0]
        self.assertGreater(num(up["p_final_pa"]), num(up["p_initial_pa"]) + 300e3)

        # Chirp: a finite bandwidth in a physical range; gain falls from the low frequencies.
        points = table(out, "chirp.csv")
        critical = num(points[0]["critical_hz"])
        self.assertTrue(2 < critical < 200, critical)
        self.assertLess(num(points[-1]["gain_db"]), -3)

        # Force: the fingertip estimates are grams to a kilogram, from a tension near full supply.
        force = table(out, "force.csv")[0]
        for key in ("flex_tip_n", "ext_tip_n"):
            self.assertTrue(0.5 < num(force[key]) < 20, force)
        self.assertGreater(num(force["flex_tension_n"]), 20)

    def test_2_refuses_with_another_commander(self):
        self.release()  # the watchdog latched when the quick run stopped commanding
        time.sleep(0.5)
        other = rospy.Publisher("/adroit/valve_command", ValveCommand, queue_size=1)
        time.sleep(0.5)
        try:
            code, log = run_tool("characterise_other", os.path.join(self.dir, "other"), "_wait_timeout:=5")
        finally:
            other.unregister()
        fatal = [l for l in log.splitlines() if "FATAL" in l]
        self.assertNotEqual(code, 0, log)
        self.assertEqual(len(fatal), 1, log)
        self.assertIn("refusing to run", fatal[0])
        self.assertIn("also publishes /adroit/valve_command", fatal[0])

    def test_3_refuses_when_estopped(self):
        self.assertTrue(self.estop().success)
        code, log = run_tool("characterise_estopped", os.path.join(self.dir, "estopped"), "_wait_timeout:=5")
        fatal = [l for l in log.splitlines() if "FATAL" in l]
        self.assertNotEqual(code, 0, log)
        self.assertEqual(len(fatal), 1, log)
        self.assertIn("refusing to run: the driver is in its safe state (e-stop latched", fatal[0])
        self.assertFalse(os.path.exists(os.path.join(self.dir, "estopped", "report.md")))


if __name__ == "__main__":
    rostest.rosrun("adroit_driver", "characterise", Characterise)
    mark_probe_skips()
