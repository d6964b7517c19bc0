# Sourced by every script: the environment ROS tools need on this machine.
# ROS's Python tools (catkin, rostest, hztest) need Debian's python3 with catkin_pkg and
# rospy; a pyenv python3 earlier on PATH lacks them, so /usr/bin goes first.
export PATH=/usr/bin:/bin:$PATH
export PYTHONNOUSERSITE=1
unset PYTHONPATH PYENV_VERSION
WS_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
export WS_ROOT
export ROS_HOME="${ROS_HOME:-$WS_ROOT/log/ros}"
# Node output in order when it goes to a pipe or a log file, not in blocks at exit.
export ROSCONSOLE_STDOUT_LINE_BUFFERED=1 PYTHONUNBUFFERED=1
mkdir -p "$ROS_HOME"
source_workspace() {
  # colcon's setup scripts reference unset variables; relax nounset while sourcing.
  set +u
  # shellcheck disable=SC1091
  source "$WS_ROOT/install/setup.bash"
  set -u
}
