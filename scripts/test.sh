#!/usr/bin/env bash
# The README's test command: install, build, run every test (gtest units and rostest
# integrations), end with one line 'N passed, N failed'; exit non-zero on any failure.
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
rm -rf build/*/test_results
# Tests run one package at a time: rostest integrations start their own roscore on a
# random port, but timing-sensitive checks should not share 2 cores with another suite.
colcon --log-base log test --parallel-workers 1 --event-handlers console_cohesion+ summary+ status- "$@"
python3 "$here/count_results.py" build
