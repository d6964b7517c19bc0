"""behaviour_through_launch.py's pure parts: the options, the seeded draws, a run's row from a
probe's result, the totals and the RESULT lines (targets scaled to the runs)."""
import math
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from behaviour_probes import parse_catch  # noqa: E402
from behaviour_through_launch import (ArgumentError, group_cores, parse_args, relocate_offsets,  # noqa: E402
                                      result_lines, run_row, summarise, type_sequences)


def probe_result(**extra):
    r = {"cores": {"adroit_sim": {"fifo": 0.3, "normal": 0.05}, "adroit/pool_manager": {"fifo": 0.2}, "adroit/pools": {},
                   "robot_state_publisher": {"normal": 0.02}, "rosmaster": {"normal": 0.04},
                   "adroit_mpc": {"niced": 0.9, "fifo": 0.1}, "rviz": {"normal": 0.01}},
         "iteration_ms": [30.0, 40.0, 50.0], "policy_age_ms": [60.0, 70.0, 80.0], "watchdog_trips": 0,
         "slowdown_fraction": 0.001, "stall_ms": 12.0, "window_s": 5.0}
    r.update(extra)
    return r


def test_options_default_and_bad_ones_give_one_line():
    args = parse_args([])
    assert args.tasks == ["catch", "relocate", "type"] and args.runs == 10 and args.mode == "pneumatic"
    for bad in (["--tasks", "catch,juggle"], ["--runs", "0"], ["--mode", "hydraulic"], ["--planner", "x"],
                ["--runs", "many"], ["--tasks", "type,type"], ["--frobnicate"]):
        with pytest.raises(ArgumentError) as e:
            parse_args(bad)
        assert "\n" not in str(e.value)


def test_draws_are_seeded_and_in_mpc_successs_boxes():
    assert relocate_offsets(1, 5) == relocate_offsets(1, 5) != relocate_offsets(2, 5)
    for start, goal in relocate_offsets(1, 200):
        assert abs(start[0]) <= 0.015 and abs(start[1]) <= 0.015 and 0.04 <= start[2] <= 0.09
        assert math.hypot(*goal) >= 0.05
        assert abs(goal[0]) <= 0.08 and abs(goal[1]) <= 0.06 and -0.1 <= goal[2] <= 0
    sequences = type_sequences(1, 3)
    assert sequences == type_sequences(1, 3) and all(len(s) == 10 and s.isdigit() for s in sequences)


def test_cores_by_group_and_a_run_row():
    groups = group_cores(probe_result()["cores"])
    assert groups["driver"] == pytest.approx(0.35) and groups["pools"] == pytest.approx(0.2)
    assert groups["mpc"] == pytest.approx(1.0) and groups["other"] == pytest.approx(0.01)
    row = run_row("catch", 0, probe_result(success=True, distance_cm=0.8))
    assert row["run"] == 1 and row["success"] and row["iteration_ms"] == 40.0 and row["policy_age_ms"] == 70.0
    assert row["stack_without_mpc"] == pytest.approx(0.35 + 0.2 + 0.02 + 0.04 + 0.01)
    failed = run_row("relocate", 1, {"error": "the probe gave no result"})
    assert not failed["success"] and math.isnan(failed["iteration_ms"]) and failed["mpc"] == 0


def test_demo_reports_verdict_is_parsed():
    text = ("== catch: bottle dropped 7.0 cm above the goal ==\nafter 3.0 s it is 0.8 cm from the goal (tolerance "
            "3 cm), lowest height 0.371 m (palm 0.2 m): CAUGHT\n")
    assert parse_catch(text) == {"caught": True, "distance_cm": 0.8, "lowest_m": 0.371}
    assert parse_catch(text.replace("CAUGHT", "NOT caught"))["caught"] is False
    assert parse_catch("demo_report: the behaviour MPC published nothing")["caught"] is None


def test_result_lines_scale_the_targets_to_the_runs():
    catch = [run_row("catch", k, probe_result(success=k < 9)) for k in range(10)]
    relocate = [run_row("relocate", k, probe_result(success=k < 2, distance_cm=1.0)) for k in range(3)]
    typing = [run_row("type", k, probe_result(success=False, keys_right=9, keys=10, unasked=k, presses=11,
                                              wrong_presses=1)) for k in range(2)]
    summaries = [summarise("catch", catch, 0.02), summarise("relocate", relocate, 0.02),
                 summarise("type", typing, 0.02)]
    lines = [line for line in result_lines(summaries, "pneumatic", "ilqg") if line.startswith("RESULT")]
    assert lines == ["RESULT adroit_launch/demo_catch_successes 9 of 10 target >= 9 PASS",
                     "RESULT adroit_launch/relocate_successes 2 of 3 target >= 3 FAIL",
                     "RESULT adroit_launch/type_pneumatic_keys_right_percent 90.0 % target >= 90 PASS",
                     "RESULT adroit_launch/type_unasked_keys 1 keys target <= 0 FAIL"]
    assert summaries[2]["presses"] == 22 and summaries[2]["wrong_presses"] == 2
    force = [line.split()[1] for line in result_lines(summaries, "force", "cem") if line.startswith("RESULT")]
    assert force == ["adroit_launch/demo_catch_successes_force_cem", "adroit_launch/relocate_successes_force_cem",
                     "adroit_launch/type_force_keys_right_percent_cem", "adroit_launch/type_unasked_keys_force_cem"]


def test_the_machine_figures_follow_each_tasks_lines():
    rows = [run_row("catch", k, probe_result(success=True, slowdown_fraction=f, stall_ms=s))
            for k, (f, s) in enumerate([(0.001, 10.0), (0.05, 80.0), (0.004, 20.0)])]
    lines = result_lines([summarise("catch", rows, 0.02)], "pneumatic", "ilqg")
    assert lines[0] == "RESULT adroit_launch/demo_catch_successes 3 of 3 target >= 3 PASS"
    assert "0.4 % of the time over 2x" in lines[1] and "worst 5.0 %" in lines[1]
    assert "longest stall 80 ms" in lines[1] and "1 of 3 runs" in lines[1]
