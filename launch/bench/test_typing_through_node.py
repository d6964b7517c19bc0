"""presses_and_wrong (typing_through_node.py) counts the node's /adroit/mpc/typed keys as the typing
task counts them (TypeTask::presses, wrongPresses; adroit_mpc test_typing has the same examples)."""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from typing_through_node import keys_right, presses_and_wrong  # noqa: E402


def test_a_wrong_key_fixed_by_backspace_is_one_wrong_press_and_every_key_right():
    typed = ["4", "8", "bs", "7"]
    assert keys_right(typed, "47") == 2
    assert presses_and_wrong(typed, "47") == (4, 1)


def test_backspaces_deleting_a_right_key_or_nothing_are_wrong():
    assert presses_and_wrong(["bs", "1", "bs"], "12") == (3, 2)


def test_two_wrong_keys_need_two_backspaces_before_the_intended_key():
    # 6 and 9 wrong, both backspaced, then 5: two wrong presses of five.
    assert presses_and_wrong(["6", "9", "bs", "bs", "5"], "5") == (5, 2)
    # The intended key pressed while a backspace is due is wrong too (it lands after the wrong key).
    assert presses_and_wrong(["6", "5", "bs", "bs", "5"], "5") == (5, 2)


def test_keys_after_the_sequence_is_done_are_wrong():
    assert presses_and_wrong(["1", "1"], "1") == (2, 1)
    assert presses_and_wrong([], "12") == (0, 0)
