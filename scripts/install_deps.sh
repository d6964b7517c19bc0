#!/usr/bin/env bash
# Installs every Debian package the workspace needs to build, test, run and benchmark.
# One list, one place. Uses sudo when not root. Safe to run again.
set -euo pipefail
export DEBIAN_FRONTEND=noninteractive

PACKAGES=(
  # build tools
  build-essential cmake colcon python3-colcon-ros python3-colcon-cmake python3-colcon-bash
  python3-colcon-test-result python3-colcon-output python3-colcon-package-selection
  python3-colcon-parallel-executor python3-colcon-library-path python3-colcon-metadata
  python3-colcon-defaults python3-colcon-recursive-crawl
  # ROS 1 (Debian packaging): C++ libraries and tools
  ros-core-dev ros-desktop-dev librosbag-dev libtf2-ros-dev librostest-dev
  ros-robot-state-publisher librobot-state-publisher-dev joint-state-publisher
  joint-state-publisher-gui libnodeletlib-dev libnodelet-dev libnodeletlib-tools rviz
  # behaviour MPC node: dynamic_reconfigure (C++ server; its .cfg generator is Python, run
  # at build time), interactive goal marker, rviz markers
  libdynamic-reconfigure-config-init-mutex-dev python3-dynamic-reconfigure
  libinteractive-markers-dev libvisualization-msgs-dev
  # ROS command-line programs the scripts, tests and README call by name
  rosbash python3-rosbag python3-roslaunch python3-rosparam python3-rostopic python3-rosservice python3-rosnode
  # Python modules imported by the rostests and the Python nodes (ros-desktop-dev brings
  # only the C++ side of the messages)
  python3-rospy python3-rospkg python3-rostest python3-tf2-ros python3-std-msgs
  python3-std-srvs python3-sensor-msgs python3-geometry-msgs python3-nav-msgs
  python3-diagnostic-msgs python3-rosgraph-msgs
  # description: URDF parsing and KDL forward kinematics
  liburdfdom-dev liburdfdom-tools libkdl-parser-dev liborocos-kdl-dev
  # simulation
  libmujoco-dev libmujoco-samples libqhull-dev
  # numerics, config, testing, benchmarks
  libeigen3-dev libyaml-cpp-dev libgtest-dev libgmock-dev libbenchmark-dev python3-numpy
  # neural-network policies (adroit_learning_network, thesis 11.6): libtorch on the CPU, and
  # OpenBLAS for its libblas.so.3 (without recommends the reference BLAS may be all there is,
  # several times slower for the training's matrix products)
  libtorch-dev libopenblas0-pthread
  # the workspace's own tests: its result counting; readelf for the check that no core
  # library links a ROS library (scripts/test_core_links.py)
  python3-pytest binutils
  # the fuzz stage (scripts/test_fuzz.sh): clang with libFuzzer and its sanitizer runtimes
  clang libclang-rt-14-dev
  # generate_model.py reads the cylinder catalogue adroit_description/config/cylinders.yaml
  python3-yaml
  # screenshots of rviz under a virtual display; offscreen MuJoCo frames (render_states: a
  # hidden GLFW window under xvfb-run, which needs xauth); plots and image strips
  xvfb xauth x11-apps imagemagick libglfw3-dev python3-matplotlib
)

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ "${#missing[@]}" -eq 0 ]; then
  echo "install_deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi
echo "install_deps: installing ${#missing[@]} packages: ${missing[*]}"
$SUDO apt-get update -qq
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
