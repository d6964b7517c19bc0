#!/usr/bin/env bash
# The README's test command: install, build, run every test (gtest units and rostest
# integrations of the packages, the workspace scripts' own tests), end with one line
# 'N passed, N failed' that counts every case, a crashed or timed-out rostest included;
# exit non-zero on any failure.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
source "$here/env.sh"
cd "$WS_ROOT"

"$here/install_deps.sh" || { echo "install failed"; echo "0 passed, 1 failed"; exit 1; }
if ! "$here/build.sh"; then
  echo "build failed"
  echo "0 passed, 1 failed"
  exit 1
fi
rm -rf build/*/test_results build/*/Testing/Temporary/LastTestsFailed*.log
failed_commands=()

# Tests run one package at a time: rostest integrations start their own roscore on a
# random port, but timing-sensitive checks should not share 2 cores with another suite.
colcon --log-base log test --parallel-workers 1 --return-code-on-test-failure \
  --event-handlers console_cohesion+ summary+ "$@" || failed_commands+=("colcon test")

# The workspace scripts' own tests (the result counting below), as one more result file,
# through catkin's wrapper like every package test: no result file gives a MISSING failure.
result="$WS_ROOT/build/workspace_scripts/test_results/workspace_scripts/pytest-test_count_results.xml"
python3 /usr/share/catkin/cmake/test/run_tests.py --return-code "$result" \
  "python3 -m pytest -q -p no:cacheprovider $here/test_count_results.py --junitxml=$result" \
  || failed_commands+=("pytest scripts")

args=()
for c in "${failed_commands[@]}"; do args+=(--failed-command "$c"); done
python3 "$here/count_results.py" build "${args[@]}"
