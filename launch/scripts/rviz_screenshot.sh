#!/usr/bin/env bash
# Regenerates a screenshot of rviz under a virtual display (Xvfb, software GL).
# usage: rviz_screenshot.sh OUTPUT.png [roslaunch file and args...]
#   e.g. rviz_screenshot.sh docs/view.png adroit_launch view.launch scene:=arm_hand
# Starts its own roscore (random port) and stops everything it started.
set -euo pipefail
out="$1"; shift
[ $# -gt 0 ] || set -- adroit_launch view.launch
export PATH=/usr/bin:$PATH
display=":$((90 + RANDOM % 100))"
port=$((20000 + RANDOM % 20000))
export ROS_MASTER_URI="http://localhost:$port"
export DISPLAY="$display" LIBGL_ALWAYS_SOFTWARE=1
Xvfb "$display" -screen 0 1200x800x24 >/dev/null 2>&1 &
xvfb=$!
roscore -p "$port" >/dev/null 2>&1 &
core=$!
cleanup() { kill "${launch:-}" "$core" "$xvfb" 2>/dev/null || true; wait 2>/dev/null || true; }
trap cleanup EXIT
sleep 3
roslaunch "$@" >/tmp/rviz_screenshot_launch.log 2>&1 &
launch=$!
sleep "${SCREENSHOT_WAIT:-15}"
mkdir -p "$(dirname "$out")"
xwd -root -display "$display" | convert xwd:- "$out"
echo "screenshot written to $out"
