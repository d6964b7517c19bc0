#!/usr/bin/python3
"""Counts the test cases of a `colcon test` run from the JUnit files under build/.

Several build directories may be named (test.sh: build/ and the sanitizer tree build-asan/);
their cases are counted together.

Prints each failing case and a final line 'N passed, N failed'. Exit 1 if anything failed
or no test ran at all. Every way a test can go wrong is counted as a failure:

* a failing or erroring case in any result file (gtest-*, rosunit-*, pytest, ...);
* a result file that cannot be read (a test node killed while writing it);
* catkin's MISSING-*.xml placeholder (a gtest binary or rostest that wrote no result);
* a rostest wrapper case (rostest-*.xml, one case `test<name>` per <test> tag) that failed
  while its test node's own file rosunit-<name>.xml is missing, unreadable or shows no
  failure: the node crashed, timed out or never started. Its inner cases are counted once,
  from the inner file; the wrapper adds a case only where the inner file cannot speak;
* a ctest test listed as failed (non-zero exit, e.g. a sanitizer report at exit) whose
  result file shows no failure;
* a runner named with --failed-command (it exited non-zero) when no result shows a failure.
"""
import argparse
import glob
import os
import sys
import xml.etree.ElementTree as ET

WRAPPER_PREFIX = "rostest-"
WRAPPER_CLASS = "rostest.runner.RosTest"


class Count:
    def __init__(self):
        self.passed = self.failed = self.skipped = 0
        self.failures = []

    def fail(self, what, detail=""):
        self.failed += 1
        self.failures.append((what, detail))


def read_cases(path):
    """(name, outcome, detail) per test case, outcome in pass/fail/skip, detail the failure's text;
    None if unreadable or empty."""
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return None
    cases = []
    for case in root.iter("testcase"):
        name = f"{case.get('classname', '')}.{case.get('name', '')}"
        problem = case.find("failure")
        problem = problem if problem is not None else case.find("error")
        if problem is not None:
            detail = "\n".join(t for t in (problem.get("message", ""), problem.text or "") if t.strip())
            cases.append((name, "fail", detail))
        elif case.find("skipped") is not None:
            cases.append((name, "skip", ""))
        else:
            cases.append((name, "pass", ""))
    return cases or None


def add_cases(count, path, cases):
    failed = False
    for name, outcome, detail in cases:
        if outcome == "fail":
            count.fail(f"{path}: {name}", detail)
            failed = True
        elif outcome == "skip":
            count.skipped += 1
        else:
            count.passed += 1
    return failed


def ctest_failures(package_build_dir):
    """Result-file stems of the ctest tests that failed: '_ctest_<pkg>_gtest_test_x' -> 'gtest-test_x'."""
    log = os.path.join(package_build_dir, "Testing", "Temporary", "LastTestsFailed.log")
    pkg = os.path.basename(package_build_dir)
    stems = []
    if os.path.exists(log):
        for line in open(log, encoding="utf-8", errors="replace"):
            name = line.strip().split(":", 1)[-1]
            prefix = f"_ctest_{pkg}_"
            if name.startswith(prefix):
                kind, _, rest = name[len(prefix):].partition("_")
                stems.append(f"{kind}-{rest[:-5] if rest.endswith('.test') else rest}")
            elif name:
                stems.append(name)
    return stems


def count_package(count, package_build_dir):
    files = sorted(glob.glob(f"{package_build_dir}/test_results/**/*.xml", recursive=True))
    outcome_by_stem = {}  # result-file stem -> True if it counted a failure
    wrappers = [f for f in files if os.path.basename(f).startswith(WRAPPER_PREFIX)]
    claimed = set()  # inner files a wrapper speaks for

    for wrapper in wrappers:
        cases = read_cases(wrapper)
        stem = os.path.basename(wrapper)[:-4]
        if cases is None:
            count.fail(f"{wrapper}: unreadable rostest result")
            outcome_by_stem[stem] = True
            continue
        wrapper_failed = False
        for name, outcome, _ in cases:
            test_name = name.split(".")[-1]
            inner = os.path.join(os.path.dirname(wrapper), f"rosunit-{test_name[4:]}.xml")
            if not name.startswith(WRAPPER_CLASS + ".test"):
                inner = None
            inner_cases = read_cases(inner) if inner and os.path.exists(inner) else None
            if inner:
                claimed.add(inner)
            if inner_cases is None:
                # The test node wrote nothing usable: the wrapper's verdict is the only one.
                why = "no result from the test node (crashed, timed out or never started)"
                wrapper_failed |= add_cases(count, wrapper, [(f"{name}: {why}", outcome, "")])
                continue
            inner_failed = add_cases(count, inner, inner_cases)
            wrapper_failed |= inner_failed
            if outcome == "fail" and not inner_failed:
                count.fail(f"{wrapper}: {name}: rostest failed although the node's results passed")
                wrapper_failed = True
        outcome_by_stem[stem] = wrapper_failed

    for path in files:
        if path in claimed or path in wrappers:
            continue
        cases = read_cases(path)
        stem = os.path.basename(path)[:-4]
        if cases is None:
            count.fail(f"{path}: unreadable or empty result file")
            outcome_by_stem[stem] = True
        else:
            outcome_by_stem[stem] = add_cases(count, path, cases)

    for stem in ctest_failures(package_build_dir):
        if not outcome_by_stem.get(stem, False) and not outcome_by_stem.get(f"MISSING-{stem}", False):
            count.fail(f"{package_build_dir}: ctest test {stem} exited non-zero although its results passed")


def excerpt(detail, head=10, tail=40):
    """The failure text a CI log can show: its first and last lines (the assertion and the output
    it quotes), so a failure on a machine we cannot log into still says why."""
    lines = [l.rstrip() for l in detail.splitlines() if l.strip()]
    if len(lines) <= head + tail:
        return lines
    return lines[:head] + [f"... ({len(lines) - head - tail} lines left out)"] + lines[-tail:]


def main(build_dirs, failed_commands=()):
    """build_dirs: one build directory or a list of them."""
    if isinstance(build_dirs, str):
        build_dirs = [build_dirs]
    count = Count()
    for build_dir in build_dirs:
        for package_build_dir in sorted(glob.glob(f"{build_dir}/*/")):
            count_package(count, package_build_dir.rstrip("/"))
    if count.failed == 0:
        # A runner that failed without any failing result left a failure we cannot see.
        for command in failed_commands:
            count.fail(f"{command} exited non-zero with no failing result")
    for what, detail in count.failures:
        print(f"FAILED {what}")
        for line in excerpt(detail):
            print(f"    {line}")
    line = f"{count.passed} passed, {count.failed} failed"
    if count.skipped:
        line += f", {count.skipped} skipped"
    print(line)
    return 0 if count.failed == 0 and count.passed > 0 else 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("build_dirs", nargs="*", default=["build"], metavar="build_dir",
                        help="colcon build directories (default: build)")
    parser.add_argument("--failed-command", action="append", default=[],
                        help="a test runner that exited non-zero (counted if no result shows why)")
    args = parser.parse_args()
    sys.exit(main(args.build_dirs, args.failed_command))
