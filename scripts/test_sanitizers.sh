#!/usr/bin/env bash
# Sanitizer stage of scripts/test.sh: builds the packages that hold the ROS-free core
# libraries (adroit_core, adroit_description, adroit_pneumatics, adroit_driver,
# adroit_learning, and what they need) with AddressSanitizer + UndefinedBehaviorSanitizer
# (LeakSanitizer included) into build-asan/ and install-asan/, then runs their gtest unit
# tests (not the rostests) there.
# Any sanitizer report fails the test binary: ASan and LSan stop at the first report
# (halt_on_error) with a non-zero exit code, UBSan cannot recover
# (-fno-sanitize-recover=undefined). The results land in build-asan/*/test_results, which
# test.sh counts with build/. Exit status non-zero if the build or a test failed.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
source "$here/env.sh"
cd "$WS_ROOT" || exit 1

BUILD_BASE=build-asan  # test.sh counts its results beside build/'s
INSTALL_BASE=install-asan
PACKAGES=(adroit_core adroit_description adroit_pneumatics adroit_driver adroit_learning)

# No result of an earlier run may count if this build fails.
rm -rf "$BUILD_BASE"/*/test_results "$BUILD_BASE"/*/Testing/Temporary/LastTestsFailed*.log

sanitize="-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined"
# colcon.meta still applies (its build type is Release); the Release flags are replaced by
# -O1 -g, the usual sanitizer build (readable stacks, fast enough). Linking takes
# CMAKE_CXX_FLAGS, so executables and shared libraries get the sanitizer runtimes.
if ! "$here/build.sh" --build-base "$BUILD_BASE" --install-base "$INSTALL_BASE" \
    --packages-up-to "${PACKAGES[@]}" \
    --cmake-args "-DCMAKE_CXX_FLAGS=$sanitize" "-DCMAKE_C_FLAGS=$sanitize" \
    "-DCMAKE_CXX_FLAGS_RELEASE=-O1 -g" "-DCMAKE_C_FLAGS_RELEASE=-O1 -g"; then
  echo "sanitizer build failed"
  exit 1
fi

# exitcode: a distinctive status for a report found at exit (LSan's leak check runs then).
export ASAN_OPTIONS="halt_on_error=1:exitcode=23:detect_leaks=1:detect_stack_use_after_return=1:check_initialization_order=1:strict_init_order=1"
export UBSAN_OPTIONS="halt_on_error=1:exitcode=23:print_stacktrace=1"
export LSAN_OPTIONS="exitcode=23"
# Only catkin's gtest targets (_ctest_<pkg>_gtest_<name>); the rostests need a ROS master.
colcon --log-base log test --build-base "$BUILD_BASE" --install-base "$INSTALL_BASE" \
  --packages-select "${PACKAGES[@]}" --parallel-workers 1 --return-code-on-test-failure \
  --event-handlers console_cohesion+ summary+ --ctest-args -R _gtest_
