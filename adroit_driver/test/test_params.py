#!/usr/bin/python3
"""Bad parameters: non-zero exit and one clear error line naming the parameter."""
import os
import subprocess
import tempfile
import unittest

import rospkg
import rospy
import rostest


def run_driver(name, *params, node="adroit_sim"):
    cmd = ["rosrun", "adroit_driver", node, "__name:=" + name] + list(params)
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, timeout=60, text=True)
    fatal = [l for l in (proc.stdout + proc.stderr).splitlines() if "FATAL" in l]
    return proc.returncode, fatal


class Params(unittest.TestCase):
    def check(self, name, params, *expected, node="adroit_sim"):
        code, fatal = run_driver(name, *params, node=node)
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

    # A misspelt key would run at its default without a word: every node refuses it, naming
    # the key it resembles.
    def test_misspelt_keys_are_refused(self):
        for node in ("adroit_sim", "adroit_hw"):
            name = "misspelt_" + node
            self.check(name, ["_watchdog_timout:=0.5"], "bad parameter /%s/watchdog_timout: unknown parameter "
                       "(did you mean watchdog_timeout?)" % name, node=node)
        self.check("misspelt_sensor", ["_sensors/joint_nois_std:=0.01"], "bad parameter /misspelt_sensor/sensors/"
                   "joint_nois_std: unknown parameter (did you mean joint_noise_std?)")
        self.check("misspelt_emulator", ["_sensor_realsim:=false"], "bad parameter /misspelt_emulator/sensor_realsim: "
                   "unknown parameter (did you mean sensor_realism?)", node="adroit_can_emulator")

    def test_every_key_of_the_shipped_configs_is_known(self):
        # Keys are checked in sorted order: a refusal of the last one means all others passed.
        config = os.path.join(rospkg.RosPack().get_path("adroit_driver"), "config")
        for node, yaml, key in (("adroit_sim", "sim.yaml", "zz_unknown"), ("adroit_sim", "sim.yaml", "sensors/zz_unknown"),
                                ("adroit_hw", "hardware.yaml", "zz_unknown"),
                                ("adroit_can_emulator", "emulator.yaml", "zz_unknown")):
            name = "config_" + node + "_" + key.replace("/", "_")
            subprocess.run(["rosparam", "load", os.path.join(config, yaml), "/" + name], check=True, timeout=30)
            self.check(name, ["_%s:=1" % key], "bad parameter /%s/%s: unknown parameter" % (name, key), node=node)


if __name__ == "__main__":
    rospy.init_node("test_params", anonymous=True)
    rostest.rosrun("adroit_driver", "params", Params)
