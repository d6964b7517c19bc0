#!/usr/bin/env bash
# The README's demo command: install, build, run the main demo headless.
# The demo is the simulated robot (MuJoCo + pneumatic plant) in real time with the iLQG
# force-abstraction pools tracking a finger open/close wave in the coffee-bean tube scene;
# after 20 s demo_report prints what happened and the launch ends.
# Extra arguments go to roslaunch, e.g. `bash scripts/demo.sh rviz:=true scene:=keypad`.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
source "$here/env.sh"
cd "$WS_ROOT"
"$here/install_deps.sh"
"$here/build.sh"
source_workspace
echo
echo "== the ADROIT scenes (3 simulated seconds each, zero tension) =="
rosrun adroit_description scene_report --seconds 3
echo
echo "== sim bringup: driver + pneumatic pools + demo motion, 20 s =="
# A private master on a free port, so the demo never collides with a running ROS system.
port=$((20000 + RANDOM % 20000))
exec roslaunch -p "$port" adroit_launch demo.launch "$@"
