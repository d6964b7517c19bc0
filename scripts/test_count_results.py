"""Tests of count_results.py on hand-made result trees shaped like what catkin, gtest and
rostest write (the shapes were taken from real runs: a crashed test node leaves only a
failing wrapper case, a timed-out one an empty rosunit file, a gtest binary that wrote
nothing catkin's MISSING-*.xml placeholder)."""
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import count_results  # noqa: E402


def suite(*cases):
    body = "".join(cases)
    return f'<?xml version="1.0" encoding="utf-8"?><testsuite name="s" tests="{len(cases)}">{body}</testsuite>'


def case(classname, name, outcome="pass"):
    inner = {"pass": "", "fail": '<failure message="boom"/>', "error": '<error message="boom"/>',
             "skip": "<skipped/>"}[outcome]
    return f'<testcase classname="{classname}" name="{name}" time="0.1">{inner}</testcase>'


def wrapper_case(test_name, outcome="pass"):
    return case("rostest.runner.RosTest", "test" + test_name, outcome)


MISSING = ('<?xml version="1.0" encoding="UTF-8"?>\n<testsuite tests="1" failures="1" time="1" errors="0" '
           'name="gtest-test_x.xml">\n  <testcase name="test_ran" status="run" time="1" classname="Results">\n'
           '    <failure message="Unable to find test results for gtest-test_x.xml, test did not run." type=""/>\n'
           '  </testcase>\n</testsuite>')


class Tree:
    def __init__(self, root, package="pkg"):
        self.build = root / "build"
        self.package = package
        self.results = self.build / package / "test_results" / package
        self.results.mkdir(parents=True)

    def write(self, name, text):
        (self.results / name).write_text(text)

    def ctest_failed(self, *names):
        log = self.build / self.package / "Testing" / "Temporary"
        log.mkdir(parents=True)
        (log / "LastTestsFailed.log").write_text("".join(f"{i + 1}:{n}\n" for i, n in enumerate(names)))

    def count(self, capsys):
        code = count_results.main(str(self.build))
        lines = capsys.readouterr().out.strip().splitlines()
        return code, lines[-1], lines[:-1]


@pytest.fixture
def tree(tmp_path):
    return Tree(tmp_path)


def test_passing_rostest_counts_the_node_cases_once(tree, capsys):
    tree.write("rostest-test_ok.xml", suite(wrapper_case("ok")))
    tree.write("rosunit-ok.xml", suite(case("__main__.T", "a"), case("__main__.T", "b"), case("__main__.T", "c")))
    assert tree.count(capsys) == (0, "3 passed, 0 failed", [])


def test_rostest_whose_node_crashed_counts_as_failed(tree, capsys):
    tree.write("rostest-test_crash.xml", suite(wrapper_case("crasher", "fail")))
    code, line, failures = tree.count(capsys)
    assert (code, line) == (1, "0 passed, 1 failed")
    assert "crasher" in failures[0] and "no result from the test node" in failures[0]


def test_timed_out_node_with_an_empty_result_file_fails_once(tree, capsys):
    tree.write("rostest-test_slow.xml", suite(wrapper_case("sleeper", "error")))
    tree.write("rosunit-sleeper.xml", "")
    assert tree.count(capsys)[:2] == (1, "0 passed, 1 failed")


def test_failing_node_cases_are_not_doubled_by_the_wrapper(tree, capsys):
    tree.write("rostest-test_bad.xml", suite(wrapper_case("bad", "fail")))
    tree.write("rosunit-bad.xml", suite(case("__main__.T", "a"), case("__main__.T", "b", "fail")))
    assert tree.count(capsys)[:2] == (1, "1 passed, 1 failed")


def test_wrapper_failure_with_passing_node_results_still_fails(tree, capsys):
    # e.g. the node wrote its results, then died during teardown
    tree.write("rostest-test_late.xml", suite(wrapper_case("late", "fail")))
    tree.write("rosunit-late.xml", suite(case("__main__.T", "a")))
    assert tree.count(capsys)[:2] == (1, "1 passed, 1 failed")


def test_rostest_with_several_nodes_one_crashed(tree, capsys):
    tree.write("rostest-test_multi.xml", suite(wrapper_case("hz", "pass"), wrapper_case("dead", "fail")))
    tree.write("rosunit-hz.xml", suite(case("__main__.HzTest", "test_hz")))
    assert tree.count(capsys)[:2] == (1, "1 passed, 1 failed")


def test_gtest_binary_that_never_wrote_results(tree, capsys):
    tree.write("gtest-test_y.xml", suite(case("Y", "works")))
    tree.write("MISSING-gtest-test_x.xml", MISSING)
    tree.ctest_failed("_ctest_pkg_gtest_test_x")  # ctest saw it fail too: still one failure
    assert tree.count(capsys)[:2] == (1, "1 passed, 1 failed")


def test_binary_exiting_non_zero_after_passing_results_fails(tree, capsys):
    tree.write("gtest-test_leak.xml", suite(case("L", "a"), case("L", "b")))
    tree.ctest_failed("_ctest_pkg_gtest_test_leak")
    code, line, failures = tree.count(capsys)
    assert (code, line) == (1, "2 passed, 1 failed")
    assert "gtest-test_leak" in failures[0]


def test_unreadable_gtest_file_and_skips(tree, capsys):
    tree.write("gtest-test_cut.xml", "<testsuite><testcase name=")
    tree.write("gtest-test_s.xml", suite(case("S", "a", "skip"), case("S", "b")))
    assert tree.count(capsys)[:2] == (1, "1 passed, 1 failed, 1 skipped")


def test_missing_rostest_wrapper_placeholder_counts(tree, capsys):
    tree.write("MISSING-rostest-test_gone.xml", MISSING)
    tree.ctest_failed("_ctest_pkg_rostest_test_gone.test")
    assert tree.count(capsys)[:2] == (1, "0 passed, 1 failed")


def test_no_test_at_all_is_a_failure(tree, capsys):
    assert tree.count(capsys)[:2] == (1, "0 passed, 0 failed")


def test_runner_that_failed_without_a_failing_result(tree, capsys):
    tree.write("gtest-test_y.xml", suite(case("Y", "works")))
    assert count_results.main(str(tree.build), ["colcon test"]) == 1
    assert capsys.readouterr().out.strip().splitlines()[-1] == "1 passed, 1 failed"
    tree.write("gtest-test_z.xml", suite(case("Z", "broken", "fail")))
    assert count_results.main(str(tree.build), ["colcon test"]) == 1  # explained: not counted twice
    assert capsys.readouterr().out.strip().splitlines()[-1] == "1 passed, 1 failed"


def test_several_build_directories_are_counted_together(tmp_path, capsys):
    # test.sh counts build/ and the sanitizer tree build-asan/ in one line; the same package
    # in both counts twice, and a failure in either fails the run.
    main_tree = Tree(tmp_path / "main")
    main_tree.write("gtest-test_x.xml", suite(case("X", "a"), case("X", "b")))
    asan = Tree(tmp_path / "asan")
    asan.write("gtest-test_x.xml", suite(case("X", "a"), case("X", "b", "fail")))
    asan.ctest_failed("_ctest_pkg_gtest_test_x")
    assert count_results.main([str(main_tree.build), str(asan.build)]) == 1
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[-1] == "3 passed, 1 failed"
    assert lines[:-1] == [f"FAILED {asan.results}/gtest-test_x.xml: X.b", "    boom"]
    assert count_results.main([str(main_tree.build), str(tmp_path / "never_built")]) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1] == "2 passed, 0 failed"


def test_a_failure_prints_its_text_so_a_ci_log_says_why(tree, capsys):
    long_log = "\n".join(f"tool line {i}" for i in range(200))
    failing = ('<testcase classname="__main__.T" name="quick"><failure message="AssertionError: 1 != 0">'
               f'Traceback line\n{long_log}\nlast words</failure></testcase>')
    tree.write("rosunit-x.xml", suite(failing))
    code, line, printed = tree.count(capsys)
    assert (code, line) == (1, "0 passed, 1 failed")
    assert printed[0].startswith("FAILED ") and printed[0].endswith("__main__.T.quick")
    assert printed[1] == "    AssertionError: 1 != 0"
    assert printed[-1] == "    last words"
    assert any("lines left out" in p for p in printed)
    assert len(printed) < 60
