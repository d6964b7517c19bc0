#!/usr/bin/env bash
# Fuzz stage of scripts/test.sh: builds the libFuzzer harness of the CAN frame decoders
# (adroit_driver/test/fuzz_can_decode.cpp, with ASan + UBSan) with clang into build-fuzz/ and
# runs it for FUZZ_SECONDS (default 60) from the checked-in seed corpus. New inputs go to
# build-fuzz/corpus (the checked-in corpus is only read); a finding is written to
# build-fuzz/ and fails the stage. The result is one JUnit case, counted by test.sh.
# usage: test_fuzz.sh [seconds]
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
source "$here/env.sh"
cd "$WS_ROOT" || exit 1
seconds="${1:-${FUZZ_SECONDS:-60}}"
out=build-fuzz
result_dir="$WS_ROOT/build/workspace_scripts/test_results/workspace_scripts"
result="$result_dir/fuzz-can_decode.xml"
mkdir -p "$out/corpus" "$result_dir"
rm -f "$result"

junit() {  # junit <failure message or empty> <seconds>
  local failure=""
  [ -n "$1" ] && failure="<failure message=\"$1\"/>"
  printf '<?xml version="1.0" encoding="utf-8"?>\n<testsuite name="fuzz" tests="1" failures="%d" errors="0">\n  <testcase classname="fuzz" name="can_decode_%ss" time="%s">%s</testcase>\n</testsuite>\n' \
    "$([ -n "$1" ] && echo 1 || echo 0)" "$seconds" "$2" "$failure" > "$result"
}

start=$SECONDS
src=adroit_driver
if ! clang++ -std=c++17 -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
    -I "$src/include" "$src/test/fuzz_can_decode.cpp" "$src/src/can_frame.cpp" "$src/src/can_protocol.cpp" \
    "$src/src/can_transport.cpp" -o "$out/fuzz_can_decode"; then
  junit "the fuzzer did not build (clang with libFuzzer: clang, libclang-rt-14-dev)" 0
  exit 1
fi
"$out/fuzz_can_decode" -max_total_time="$seconds" -print_final_stats=1 -artifact_prefix="$out/" \
  "$out/corpus" "$src/test/fuzz_corpus/can_decode" > "$out/fuzz.log" 2>&1
status=$?
tail -n 12 "$out/fuzz.log"
if [ "$status" -ne 0 ]; then
  junit "finding or crash (exit $status): see $out/fuzz.log and $out/crash-*" $((SECONDS - start))
  exit 1
fi
junit "" $((SECONDS - start))
echo "fuzz stage: fuzz_can_decode ran ${seconds} s without a finding"
