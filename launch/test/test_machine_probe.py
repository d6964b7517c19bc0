"""unless_the_machine_slowed (machine_probe.py): a failure is skipped only when the probe saw the
machine itself slow down, and the probe is stopped whatever happens."""
import os
import sys
import unittest

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from machine_probe import SLOW_FRACTION, unless_the_machine_slowed  # noqa: E402


class FakeProbe:
    def __init__(self, fraction):
        self.fraction, self.stops = fraction, 0

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


def test_a_pass_stays_a_pass_and_other_errors_stay_errors():
    probe = FakeProbe(SLOW_FRACTION * 3)
    with unless_the_machine_slowed(Case(), probe):
        pass
    assert probe.stops == 1
    with pytest.raises(TimeoutError):
        with unless_the_machine_slowed(Case(), FakeProbe(SLOW_FRACTION * 3)):
            raise TimeoutError("no message")
