#!/usr/bin/env bash
# The README's demo command: install, build, run the main demo headless.
# The demo is the simulated robot (MuJoCo + pneumatic plant) in real time with the iLQG
# force-abstraction pools tracking a finger open/close wave in the coffee-bean tube scene;
# demo_report watches it for `duration` seconds (default 20), prints what happened, and the
# bringup is ended cleanly (driver paused first, so no safety event is raised by the pools
# going down before it). Exit status: demo_report's (non-zero if nothing moved).
# Extra arguments go to roslaunch, e.g. `bash scripts/demo.sh rviz:=true scene:=keypad`;
# `duration:=60` sets the report window.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
source "$here/env.sh"
cd "$WS_ROOT"
"$here/install_deps.sh"
"$here/build.sh"
source_workspace

duration=20
launch_args=()
for arg in "$@"; do
  case "$arg" in
    duration:=*) duration="${arg#duration:=}" ;;
    *) launch_args+=("$arg") ;;
  esac
done

echo
echo "== the ADROIT scenes (3 simulated seconds each, zero tension) =="
rosrun adroit_description scene_report --seconds 3
echo
echo "== sim bringup: driver + pneumatic pools + demo motion, ${duration} s =="
# A private master on a free port, so the demo never collides with a running ROS system.
port=$((20000 + RANDOM % 20000))
export ROS_MASTER_URI="http://127.0.0.1:$port"
roslaunch -p "$port" adroit_launch demo.launch "${launch_args[@]}" &
launch_pid=$!
stop_launch() {
  kill -INT "$launch_pid" 2>/dev/null || true
  wait "$launch_pid" 2>/dev/null || true
}
trap stop_launch EXIT
for _ in $(seq 150); do rosparam get /rosversion >/dev/null 2>&1 && break; sleep 0.2; done
set +e
rosrun adroit_launch demo_report.py _duration:="$duration"
report_status=$?
set -e
# Pause first: a paused driver steps no watchdog, so the pools may go down in any order.
rosservice call /adroit/pause true >/dev/null 2>&1 || true
stop_launch
trap - EXIT
exit "$report_status"
