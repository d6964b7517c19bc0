#!/usr/bin/env bash
# Latency of the hardware driver through the pools (issue 15), with its own roscore on a random port:
# hw_latency_bench plays the robot's boards on four emulated buses, adroit_hw connects to them, then
# paired blocks alternate a relay baseline and the six pools (started by the bench per block); the
# plot follows. Every process started here is stopped on exit.
# usage: run_hw_latency.sh [seconds_per_block=10] [pairs=3]
# Writes into $ADROIT_BENCH_OUT (default /tmp/adroit_hw_latency): hw_latency.csv, hw_latency.png,
# summary.txt, driver.log, pools_<block>.log. Other pools: ADROIT_HW_LATENCY_POOLS_ARGS="controller=pidf"
# (k=v, roslaunch arguments), ADROIT_HW_LATENCY_POOLS_LAUNCH="<package> <file>" or a path;
# ADROIT_HW_LATENCY_FRAMES=1 also writes every frame of each block (frames_<block>.csv).
set -euo pipefail
export PATH=/usr/bin:$PATH
here="$(dirname "$(readlink -f "$0")")"
if [[ "${1:-}" != --inner ]]; then
  exec rosrun adroit_ros with_roscore "$(readlink -f "$0")" --inner "$@"
fi
shift
seconds="${1:-10}"
pairs="${2:-3}"
scene=arm_hand
out="${ADROIT_BENCH_OUT:-/tmp/adroit_hw_latency}"
mkdir -p "$out"
rm -f "$out/pools.pgid"
bin="$here"  # installed next to this script; run from the source tree, the install space's
[[ -x "$bin/hw_latency_bench" ]] || bin="$(catkin_find --first-only --libexec adroit_driver)"
prefix="/tmp/adroit_hw_latency_$$"  # short: a socket path has at most 107 bytes

# Benchmarks want an idle machine: another ADROIT stack's real-time threads share the cores.
others="$(ps -eo comm= | grep -cE '^(adroit_hw|adroit_sim|adroit_can_emul|pool_node|nodelet)$' || true)"
[[ "$others" != 0 ]] && echo "warning: $others other ADROIT processes are running: the figures will be disturbed"

bench_pid="" driver_pid=""
cleanup() {
  [[ -n "$driver_pid" ]] && kill -INT "$driver_pid" 2>/dev/null || true
  [[ -n "$bench_pid" ]] && kill -TERM "$bench_pid" 2>/dev/null || true
  for pid in $bench_pid $driver_pid; do
    for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    kill -KILL "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
  done
  # The pools' process group, should the bench have died without stopping them.
  if [[ -f "$out/pools.pgid" ]]; then
    kill -KILL -- "-$(cat "$out/pools.pgid")" 2>/dev/null || true
    rm -f "$out/pools.pgid"
  fi
  rm -f "${prefix}"_*
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# The board player listens first: the driver connects to its paths.
options=(--bus-prefix "$prefix" --out "$out" --scene "$scene" --seconds "$seconds" --pairs "$pairs")
[[ -n "${ADROIT_HW_LATENCY_POOLS_LAUNCH:-}" ]] && options+=(--pools-launch "$ADROIT_HW_LATENCY_POOLS_LAUNCH")
[[ -n "${ADROIT_HW_LATENCY_POOLS_ARGS:-}" ]] && options+=(--pools-args "$ADROIT_HW_LATENCY_POOLS_ARGS")
[[ -n "${ADROIT_HW_LATENCY_FRAMES:-}" ]] && options+=(--frames)
"$bin/hw_latency_bench" "${options[@]}" > >(tee "$out/summary.txt") 2>&1 &
bench_pid=$!
for _ in $(seq 100); do
  n=0
  for bus in palm act0 act1 act2; do [[ -S "${prefix}_$bus" ]] && n=$((n + 1)); done
  [[ $n == 4 ]] && break
  kill -0 "$bench_pid" 2>/dev/null || break
  sleep 0.1
done

"$bin/adroit_hw" __name:=adroit_hw _scene:="$scene" _buses/palm:="unix:${prefix}_palm" \
  _buses/act0:="unix:${prefix}_act0" _buses/act1:="unix:${prefix}_act1" _buses/act2:="unix:${prefix}_act2" \
  > "$out/driver.log" 2>&1 &
driver_pid=$!

status=0
wait "$bench_pid" || status=$?
bench_pid=""
if [[ $status != 0 ]]; then
  echo "hw_latency_bench failed (status $status); the driver's log, last lines ($out/driver.log):"
  tail -n 20 "$out/driver.log"
  exit "$status"
fi
/usr/bin/python3 "$bin/plot_hw_latency.py" "$out/hw_latency.csv" "$out/hw_latency.png"
echo "plot: $out/hw_latency.png"
