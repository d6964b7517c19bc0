"""unless_the_machine_slowed (machine_probe.py): a failure is skipped only when the probe saw the
machine itself slow down, the probe is stopped whatever happens, and a skip reaches the count."""
import os
import sys
import unittest

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..", "scripts"))
import machine_probe  # noqa: E402
from count_results import read_cases  # noqa: E402
from machine_probe import SLOW_FRACTION, mark_probe_skips, unless_the_machine_slowed  # noqa: E402


class FakeProbe:
    def __init__(self, fraction, stall_ms=0.0):
        self.fraction, self.stall_ms, self.stops = fraction, stall_ms, 0

    def stop(self):
        self.stops += 1
        return self.fraction, "machine_slowdown: summary"


class Case(unittest.TestCase):
    """The test whose assertions the guard wraps (not collected itself)."""
    __test__ = False

    def runTest(self):
        pass


def test_a_failure_on_a_machine_that_kept_its_speed_fails():
    probe = FakeProbe(SLOW_FRACTION / 2)
    with pytest.raises(AssertionError, match="rms error"):
        with unless_the_machine_slowed(Case(), probe):
            raise AssertionError("rms error 0.5 rad")
    assert probe.stops >= 1


def test_a_failure_while_the_machine_slowed_down_is_skipped_with_both_reasons():
    probe = FakeProbe(SLOW_FRACTION * 3)
    with pytest.raises(unittest.SkipTest) as skipped:
        with unless_the_machine_slowed(Case(), probe):
            raise AssertionError("rms error 0.5 rad")
    assert "rms error 0.5 rad" in str(skipped.value) and "over 2x" in str(skipped.value)


def test_a_freeze_skips_only_a_test_that_gave_its_margin_and_only_from_that_margin():
    with pytest.raises(unittest.SkipTest) as skipped:
        with unless_the_machine_slowed(Case(), FakeProbe(0.0, stall_ms=45.0), freeze_limit_ms=40):
            raise AssertionError("watchdog tripped")
    assert "froze" in str(skipped.value) and "45.0 ms" in str(skipped.value)
    with pytest.raises(AssertionError, match="watchdog tripped"):  # a shorter freeze is no excuse
        with unless_the_machine_slowed(Case(), FakeProbe(0.0, stall_ms=30.0), freeze_limit_ms=40):
            raise AssertionError("watchdog tripped")
    with pytest.raises(AssertionError, match="rms error"):  # no margin given: a freeze is no excuse
        with unless_the_machine_slowed(Case(), FakeProbe(0.0, stall_ms=500.0)):
            raise AssertionError("rms error 0.5 rad")


def test_the_skip_is_written_into_the_result_file(tmp_path, monkeypatch):
    # rosunit writes a skipped case as passed: the count reads <skipped> from the file.
    result = tmp_path / "rosunit-case.xml"
    result.write_text('<testsuite><testcase classname="c" name="runTest"/><testcase classname="c" name="other"/>'
                      '</testsuite>')
    monkeypatch.setattr(sys, "argv", ["test", "--gtest_output=xml:%s" % result])
    monkeypatch.setattr(machine_probe, "SKIPPED", [])
    mark_probe_skips()  # nothing skipped: the file stays as it was
    assert "skipped" not in result.read_text()
    with pytest.raises(unittest.SkipTest):
        with unless_the_machine_slowed(Case(), FakeProbe(SLOW_FRACTION * 3)):
            raise AssertionError("watchdog tripped")
    mark_probe_skips()
    # Only the case that was skipped: the file's other cases keep their outcome.
    assert [(name, outcome) for name, outcome, _ in read_cases(str(result))] == [("c.runTest", "skip"), ("c.other", "pass")]
    assert "watchdog tripped" in result.read_text()


def test_a_pass_stays_a_pass_and_other_errors_stay_errors():
    probe = FakeProbe(SLOW_FRACTION * 3)
    with unless_the_machine_slowed(Case(), probe):
        pass
    assert probe.stops == 1
    with pytest.raises(TimeoutError):
        with unless_the_machine_slowed(Case(), FakeProbe(SLOW_FRACTION * 3)):
            raise TimeoutError("no message")
