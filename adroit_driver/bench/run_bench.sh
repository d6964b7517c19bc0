#!/usr/bin/env bash
# Runs the driver benchmark with its own roscore on a random port (nothing else is touched).
# usage: run_bench.sh [scene=ball] [lockstep_seconds=5] [realtime_seconds=10]
set -euo pipefail
export PATH=/usr/bin:$PATH
rosrun adroit_ros with_roscore "$(dirname "$(readlink -f "$0")")/driver_bench" "$@" 2>&1 | grep -v "\[ INFO\]"
