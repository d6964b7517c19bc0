// The main() of a node whose class is built from (nh, private nh): ros::init as `name`, roscpp
// started with its threads known (realtime.h: the node may put them under SCHED_FIFO), the node
// built (a bad parameter: one fatal line naming it, exit code 1), then `threads` spinner
// threads until shutdown.
#pragma once

#include <ros/ros.h>

#include "adroit_ros/params.h"
#include "adroit_ros/realtime.h"

namespace adroit::rosutil {

template <typename Node>
int runNode(int argc, char** argv, const char* name, int threads) {
  ros::init(argc, argv, name);
  startRos();
  ros::NodeHandle nh, pnh("~");
  try {
    Node node(nh, pnh);
    ros::AsyncSpinner spinner(threads);
    spinner.start();
    ros::waitForShutdown();
  } catch (const ParameterError& e) {
    ROS_FATAL("%s", e.what());
    return 1;
  }
  return 0;
}

}  // namespace adroit::rosutil
