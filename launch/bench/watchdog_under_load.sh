#!/usr/bin/env bash
# Does a loaded machine trip the command watchdog with healthy pools? The sim bringup in real
# time (driver + the five iLQG pools + the demo motion) runs for `seconds` on an idle machine
# (the baseline), then as long again with `hogs` busy-looping processes at normal priority
# (default 2 per core): watchdog trips, deadline misses and the pools' policy lag in each
# phase, then RESULT lines. Usage: watchdog_under_load.sh [seconds=60] [hogs=2*nproc]
set -euo pipefail
seconds="${1:-60}"
hogs="${2:-$((2 * $(nproc)))}"
port=$((20000 + RANDOM % 20000))
export ROS_MASTER_URI="http://127.0.0.1:$port"
roslaunch -p "$port" adroit_launch demo.launch scene:=tube >/tmp/watchdog_under_load.log 2>&1 &
launch=$!
hog_pids=()
cleanup() {
  for p in "${hog_pids[@]}"; do kill "$p" 2>/dev/null || true; done
  kill -INT "$launch" 2>/dev/null || true
  wait "$launch" 2>/dev/null || true
}
trap cleanup EXIT
for _ in $(seq 150); do rosparam get /rosversion >/dev/null 2>&1 && break; sleep 0.2; done

# key=value of the driver's (or a pool's) newest diagnostics.
diag() {  # diag <status name> <key>
  python3 - "$1" "$2" <<'PY'
import sys, rospy
from diagnostic_msgs.msg import DiagnosticArray
rospy.init_node("watchdog_probe", anonymous=True, disable_signals=True)
name, key = sys.argv[1], sys.argv[2]
while not rospy.is_shutdown():
    msg = rospy.wait_for_message("/adroit/diagnostics", DiagnosticArray, timeout=30)
    for s in msg.status:
        if s.name == name:
            print(dict((kv.key, kv.value) for kv in s.values).get(key, "?"))
            sys.exit(0)
PY
}
sleep 10  # start-up
phase() {  # phase <label>: trips and misses over `seconds`
  local trips0 misses0 trips1 misses1
  trips0=$(diag adroit_sim watchdog_trips); misses0=$(diag adroit_sim deadline_misses)
  sleep "$seconds"
  trips1=$(diag adroit_sim watchdog_trips); misses1=$(diag adroit_sim deadline_misses)
  local lag; lag=$(diag /adroit/pool_0 policy_lag_p99_ms)
  echo "$1: watchdog trips $((trips1 - trips0)), deadline misses $((misses1 - misses0)), pool_0 policy lag p99 ${lag} ms"
  eval "$2=$((trips1 - trips0))"
}
echo "== watchdog under load: ${seconds} s idle, then ${seconds} s with ${hogs} CPU hogs on $(nproc) cores =="
phase "idle  " idle_trips
for _ in $(seq "$hogs"); do (exec yes >/dev/null) & hog_pids+=($!); done
phase "loaded" loaded_trips
echo "RESULT adroit_driver/watchdog_trips_idle ${idle_trips} count target == 0 $([ "$idle_trips" = 0 ] && echo PASS || echo FAIL)"
echo "RESULT adroit_driver/watchdog_trips_under_load ${loaded_trips} count target == 0 $([ "$loaded_trips" = 0 ] && echo PASS || echo FAIL)"
