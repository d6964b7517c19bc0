#!/usr/bin/env bash
# The README's test command: install, build, run every test (gtest units and rostest
# integrations of the packages, the sanitizer build's gtests, the workspace scripts' own
# tests), end with one line 'N passed, N failed' that counts every case, a crashed or
# timed-out rostest included; exit non-zero on any failure.
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

# Sanitizer stage: the core libraries and their gtests again, built with ASan + UBSan (and
# LSan) into build-asan/ and install-asan/ (scripts/test_sanitizers.sh).
sanitizer_start=$SECONDS
"$here/test_sanitizers.sh" || failed_commands+=("sanitizer stage")
echo "sanitizer stage (ASan+UBSan build and gtests): $((SECONDS - sanitizer_start)) s wall time added"

# Fuzz stage: the CAN frame decoders' libFuzzer harness for 60 s (scripts/test_fuzz.sh).
"$here/test_fuzz.sh" 60 || failed_commands+=("fuzz stage")

# The workspace scripts' own tests (the result counting below; that no core library links a
# ROS library; that no source starts a program through a shell), the real-time tests' machine probe guard, the
# typing benchmark's press counting and the behaviour benchmark's options, totals and RESULT lines (launch/bench),
# one result file each, through catkin's wrapper like every package test: no result file gives a MISSING failure.
for t in scripts/test_count_results scripts/test_core_links scripts/test_no_shell src/adroit_core/tools/test_machine_probe \
         launch/bench/test_typing_through_node launch/bench/test_behaviour_through_launch; do
  name="$(basename "$t")"
  result="$WS_ROOT/build/workspace_scripts/test_results/workspace_scripts/pytest-$name.xml"
  python3 /usr/share/catkin/cmake/test/run_tests.py --return-code "$result" \
    "python3 -m pytest -q -p no:cacheprovider $WS_ROOT/$t.py --junitxml=$result" \
    || failed_commands+=("pytest $name")
done

args=()
for c in "${failed_commands[@]}"; do args+=(--failed-command "$c"); done
python3 "$here/count_results.py" build build-asan "${args[@]}"
