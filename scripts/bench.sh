#!/usr/bin/env bash
# Builds the workspace and runs every benchmark program. Each prints its tables next to a
# baseline measured in the same run and ends with RESULT lines (DESIGN.md section 5):
#   RESULT <package>/<figure> <value> <unit> target <op> <value> PASS|FAIL
# Run it on an otherwise idle machine.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
source "$here/env.sh"
cd "$WS_ROOT"
"$here/install_deps.sh" >/dev/null
"$here/build.sh" >/dev/null
source_workspace
mkdir -p "$WS_ROOT/log/bench"
run() {
  echo "== $* =="
  "$@" 2>&1 | tee -a "$WS_ROOT/log/bench/all.txt"
  echo
}
: > "$WS_ROOT/log/bench/all.txt"
run rosrun adroit_core noise_bench
run rosrun adroit_core lq_bench
run rosrun adroit_description scene_report --testspeed --seconds 10
run rosrun adroit_pneumatics pneumatics_bench
run rosrun adroit_pneumatics scalar_vs_core_bench
run rosrun adroit_mpc mpc_timing
run rosrun adroit_mpc mpc_success --out "$WS_ROOT/log/bench" --latency-sweep 0.01,0.03,0.05
run rosrun adroit_driver run_bench.sh ball 5 10
ADROIT_BENCH_OUT="$WS_ROOT/log/bench/hw_latency" run rosrun adroit_driver run_hw_latency.sh 10 3
run bash "$WS_ROOT/launch/bench/watchdog_under_load.sh" 60
run python3 "$WS_ROOT/launch/bench/command_margin.py" --seconds 40 --blocks 2 --out "$WS_ROOT/log/bench/command_margin"
run python3 "$WS_ROOT/launch/bench/train_command_margin.py" --iterations 3 --blocks 2 --out "$WS_ROOT/log/bench/train_command_margin"
run python3 "$WS_ROOT/launch/bench/typing_through_node.py" --sequences 3 --out "$WS_ROOT/log/bench/typing_through_node"
run rosrun adroit_teleop run_bench.sh --seconds 30 --out "$WS_ROOT/log/bench/teleop"
echo "== summary =="
grep '^RESULT' "$WS_ROOT/log/bench/all.txt"
