#!/usr/bin/env bash
# The README's demo command: install, build, run the main demo headless.
# The demo is the behaviour MPC catching a bottle in real time, in pneumatic mode: the
# simulated robot (MuJoCo + pneumatic plant), the iLQG force-abstraction pools tracking the
# MPC's planned tendon tensions, and the MPC (iLQG, task catch). Once the MPC runs,
# demo_report drops the bottle 7 cm above the palm, watches the catch for 3 s, prints what
# happened (distance to the goal, lowest height, the driver's real-time factor), and the
# bringup is ended cleanly (driver paused first, so no safety event is raised by the pools
# going down before it). The pools' force tracking is audited against the plant's floor
# (force_tracking_audit) over a rosbag recorded during the run, log/demo/forces.bag, and
# plotted into log/demo/forces.png.
# Exit status: demo_report's (non-zero when the stack did not run sound).
# Extra arguments go to roslaunch, e.g. `bash scripts/demo.sh rviz:=true planner:=sampling`;
# `task:=none` runs the earlier finger-wave demo (`duration:=60` sets its report window);
# `robot:=emulated` runs it on the hardware driver over the CAN hardware emulator (hardware.launch).
# Afterwards it renders an image strip of the run offscreen with MuJoCo (render_states under
# xvfb-run) into log/demo/demo_strip.png.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
source "$here/env.sh"
cd "$WS_ROOT"
"$here/install_deps.sh"
"$here/build.sh"
source_workspace

duration=20
task=catch
robot=sim
launch_args=()
for arg in "$@"; do
  case "$arg" in
    duration:=*) duration="${arg#duration:=}" ;;
    task:=*) task="${arg#task:=}"; launch_args+=("$arg") ;;
    robot:=*) robot="${arg#robot:=}"; launch_args+=("$arg") ;;
    *) launch_args+=("$arg") ;;
  esac
done
report_args=(_duration:="$duration")
if [ "$task" = catch ]; then report_args+=(_drop_height:=0.07 _watch:=3.0); fi
driver=adroit_sim
if [ "$robot" = emulated ]; then
  driver=adroit_hw
  report_args+=(_driver:=adroit_hw _start_with:=estop_release _place_service:=/adroit_can_emulator/set_object_pose)
elif [ "$robot" != sim ]; then
  echo "demo: robot:=$robot: expected sim or emulated" >&2
  exit 2
fi

echo
echo "== the ADROIT scenes (3 simulated seconds each, zero tension) =="
rosrun adroit_description scene_report --seconds 3
echo
echo "== $robot bringup: driver + pneumatic pools + behaviour MPC, task $task =="
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
out_dir="$WS_ROOT/log/demo"
mkdir -p "$out_dir"
rm -f "$out_dir"/states.csv "$out_dir"/frame_*.ppm "$out_dir"/forces.bag "$out_dir"/forces.bag.active
set +e
scene="$(rosparam get "/$driver/scene" 2>/dev/null)"
# The least tension the robot applies and reports (the simulation's slack-avoiding minimum; the
# hardware reports what the pressure pulls): the force audit's floors pull it too.
min_tension="$(rosparam get "/$driver/min_tension" 2>/dev/null || echo 0)"
# The pools' input and output for the force-tracking audit below (a real rosbag; SIGINT
# closes it cleanly).
rosbag record -q -O "$out_dir/forces.bag" /adroit/actuator_states /adroit/force_reference /adroit/valve_command /adroit/diagnostics \
  __name:=demo_force_bag >/dev/null 2>&1 &
bag_pid=$!
rosrun adroit_launch demo_report.py "${report_args[@]}" _states_csv:="$out_dir/states.csv" _pause_at_end:=true
report_status=$?
# demo_report paused the driver (this call makes sure): a paused driver steps no watchdog,
# so the bag's flush and the pools going down in any order cannot trip it.
rosservice call /adroit/pause true >/dev/null 2>&1 || true
kill -INT "$bag_pid" 2>/dev/null
wait "$bag_pid" 2>/dev/null
set -e
stop_launch
trap - EXIT

# The pools' force tracking over the run next to the plant's floor (pneumatic mode only:
# force mode has no force references).
if [ -s "$out_dir/forces.bag" ] && [ -n "$scene" ]; then
  echo
  rosrun adroit_pneumatics force_tracking_audit --bag "$out_dir/forces.bag" --scene "$scene" \
    --min-tension "$min_tension" --csv "$out_dir/forces.csv" || echo "demo: no force-tracking audit (no force references recorded)" >&2
  if [ -s "$out_dir/forces.csv" ]; then
    rosrun adroit_pneumatics plot_force_audit.py "$out_dir/forces.csv" "$out_dir/forces.png" \
      && echo "demo: force tracking plot $out_dir/forces.png" || echo "demo: force tracking plot not written" >&2
  fi
fi

# Six frames over the recorded run, drawn offscreen (a hidden GLFW window on a virtual display).
if [ -s "$out_dir/states.csv" ] && [ -n "$scene" ]; then
  last="$(tail -n 1 "$out_dir/states.csv" | cut -d, -f1)"
  times="$(python3 -c "print(','.join(f'{$last * k / 5:.2f}' for k in range(6)))")"
  model="$(rospack find adroit_description)/mjcf/$scene.xml"
  if xvfb-run -a rosrun adroit_description render_states --model "$model" --states "$out_dir/states.csv" \
       --times "$times" --out "$out_dir/frame"; then
    frames=()
    k=0
    for t in ${times//,/ }; do frames+=("$t:$(printf '%s/frame_%03d.ppm' "$out_dir" "$k")"); k=$((k + 1)); done
    rosrun adroit_launch image_strip.py "$out_dir/demo_strip.png" \
      "ADROIT demo: $task ($scene scene)" "${frames[@]}" || echo "demo: image strip not written" >&2
  else
    echo "demo: offscreen rendering failed; no image strip" >&2
  fi
fi
exit "$report_status"
