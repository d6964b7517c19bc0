#!/usr/bin/env bash
# Runs the driver benchmark with its own roscore on a random port (nothing else is touched).
# usage: run_bench.sh [scene=ball] [lockstep_seconds=5] [realtime_seconds=10]
set -euo pipefail
export PATH=/usr/bin:$PATH
port=$((20000 + RANDOM % 20000))
export ROS_MASTER_URI="http://localhost:$port"
roscore -p "$port" >/dev/null 2>&1 &
core=$!
trap 'kill $core 2>/dev/null || true; wait $core 2>/dev/null || true' EXIT
for _ in $(seq 50); do rosparam list >/dev/null 2>&1 && break; sleep 0.2; done
"$(dirname "$(readlink -f "$0")")/driver_bench" "$@" 2>&1 | grep -v "\[ INFO\]"
