// pool_node: one pneumatic force-abstraction pool, or a group of them (~members), as a
// standalone node (the same class runs as the nodelet adroit_pneumatics/PoolNodelet).
// Parameters: see README "Pool node".
#include <exception>
#include <memory>

#include <ros/ros.h>

#include "adroit_ros/realtime.h"

namespace adroit::pneumatics {
std::shared_ptr<void> startPool(ros::NodeHandle nh, ros::NodeHandle pnh, const std::string& name);  // pool_ros.cpp
}

int main(int argc, char** argv) {
  ros::init(argc, argv, "pool");
  adroit::rosutil::startRos();  // roscpp's threads known: the pool puts them under SCHED_FIFO
  ros::NodeHandle nh, pnh("~");
  std::shared_ptr<void> pool;
  try {
    pool = adroit::pneumatics::startPool(nh, pnh, ros::this_node::getName());
  } catch (const std::exception& e) {
    ROS_FATAL("%s: %s", ros::this_node::getName().c_str(), e.what());
    return 1;
  }
  ros::spin();
  return 0;
}
