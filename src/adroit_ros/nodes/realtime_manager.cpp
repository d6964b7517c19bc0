// realtime_manager: a nodelet manager whose roscpp threads are known (adroit_ros startRos), so
// that the nodelets it loads can put them under SCHED_FIFO as their nodes do
// (adroit_ros/realtime.h): the driver's and the pools' managers. Otherwise the stock
// `nodelet manager` (~num_worker_threads as there).
#include <nodelet/loader.h>
#include <ros/ros.h>

#include "adroit_ros/realtime.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "manager");
  adroit::rosutil::startRos();
  nodelet::Loader loader;
  ros::spin();
  return 0;
}
