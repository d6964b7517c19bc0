#!/usr/bin/python3
"""Counts test cases in the JUnit XML files that colcon/catkin wrote under build/.

Prints each failing case and a final line 'N passed, N failed'. Exit 1 if anything failed
or no test ran at all. A test binary that crashed or never wrote results is reported by
catkin as a failing 'MISSING-RESULT' case, so it is counted too.
"""
import glob
import sys
import xml.etree.ElementTree as ET

def main(build_dir):
    passed, failed, skipped = 0, 0, 0
    failures = []
    for path in sorted(glob.glob(f"{build_dir}/*/test_results/**/*.xml", recursive=True)):
        # rostest writes a wrapper file (rostest-*.xml) that repeats the node's own cases.
        if path.rsplit("/", 1)[-1].startswith("rostest-"):
            continue
        try:
            root = ET.parse(path).getroot()
        except ET.ParseError as err:
            failed += 1
            failures.append(f"{path}: unreadable result file ({err})")
            continue
        for case in root.iter("testcase"):
            name = f"{case.get('classname', '')}.{case.get('name', '')}"
            if case.find("failure") is not None or case.find("error") is not None:
                failed += 1
                failures.append(f"{path}: {name}")
            elif case.find("skipped") is not None:
                skipped += 1
            else:
                passed += 1
    for f in failures:
        print(f"FAILED {f}")
    line = f"{passed} passed, {failed} failed"
    if skipped:
        line += f", {skipped} skipped"
    print(line)
    return 0 if failed == 0 and passed > 0 else 1

if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "build"))
