#!/usr/bin/python3
"""Bad parameters: non-zero exit and one clear error line naming the parameter."""
import os
import subprocess
import tempfile
import unittest

import rospy
import rostest


def run_driver(name, *params):
    cmd = ["rosrun", "adroit_driver", "adroit_sim", "__name:=" + name] + list(params)
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=60, text=True)
    fatal = [l for l in (proc.stdout + proc.stderr).splitlines() if "FATAL" in l]
    return proc.returncode, fatal


class Params(unittest.TestCase):
    def check(self, name, params, *expected):
        code, fatal = run_driver(name, *params)
        self.assertNotEqual(code, 0)
        self.assertEqual(len(fatal), 1, fatal)
        for text in expected:
            self.assertIn(text, fatal[0])

    def test_unknown_scene(self):
        self.check("bad_scene", ["_scene:=nope"], "bad parameter /bad_scene/scene:", "unknown scene 'nope' (known:", "arm_hand")

    def test_malformed_model_names_the_path_and_mujocos_message(self):
        with tempfile.NamedTemporaryFile("w", suffix=".xml", delete=False) as f:
            f.write("<mujoco><worldbody><geom type='sphere'/></worldbody>")
        try:
            self.check("bad_model", ["_model_file:=" + f.name], f.name)
        finally:
            os.unlink(f.name)

    def test_watchdog_timeout_outside_bounds(self):
        self.check("bad_watchdog", ["_watchdog_timeout:=0.5"], "~watchdog_timeout", "[0.01, 0.2]")
        self.check("bad_watchdog_low", ["_watchdog_timeout:=0.001"], "~watchdog_timeout")

    def test_mode_and_rates(self):
        self.check("bad_mode", ["_mode:=hydraulic"], "bad parameter /bad_mode/mode:", "hydraulic")
        self.check("bad_rate", ["_joint_state_rate:=300.0"], "~joint_state_rate")
        self.check("bad_lockstep", ["_realtime:=false"], "bad parameter /bad_lockstep/realtime:", "/use_sim_time")
        self.check("bad_type", ["_timestep:=fast"], "bad parameter /bad_type/timestep: expected a number")
        self.check("bad_priority", ["_realtime_priority:=120"], "bad parameter /bad_priority/realtime_priority:", "[0, 99]")
        self.check("bad_physics", ["_physics_priority:=-1"], "bad parameter /bad_physics/physics_priority:", "[0, 99]")
        self.check("bad_nice", ["_lockstep_nice:=5"], "bad parameter /bad_nice/lockstep_nice:", "[-20, 0]")


if __name__ == "__main__":
    rospy.init_node("test_params", anonymous=True)
    rostest.rosrun("adroit_driver", "params", Params)
