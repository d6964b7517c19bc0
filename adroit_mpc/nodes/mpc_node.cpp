// adroit_mpc node: the behaviour MPC (thesis ch. 6) between the driver's state topics and its
// tendon-force command (force mode) or the pools' force references (pneumatic mode).
#include <ros/ros.h>

#include "adroit_ros/realtime.h"
#include "mpc_ros.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "adroit_mpc");
  adroit::rosutil::startRos();  // roscpp's threads known: start() puts them under SCHED_FIFO
  ros::NodeHandle nh, pnh("~");
  std::unique_ptr<adroit::mpc_node::MpcNode> node;
  try {
    node = std::make_unique<adroit::mpc_node::MpcNode>(nh, pnh);
  } catch (const std::exception& e) {
    ROS_FATAL("adroit_mpc: %s", e.what());
    return 1;
  }
  node->start();
  ros::waitForShutdown();
  node->stop();
  return 0;
}
