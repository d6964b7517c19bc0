#!/usr/bin/env bash
# Runs teleop_bench.py with its own roscore on a random port (nothing else is touched).
# usage: run_bench.sh [teleop_bench.py options: --seconds S --rate HZ --out DIR]
set -euo pipefail
export PATH=/usr/bin:$PATH
rosrun adroit_ros with_roscore /usr/bin/python3 "$(dirname "$(readlink -f "$0")")/teleop_bench.py" "$@"
