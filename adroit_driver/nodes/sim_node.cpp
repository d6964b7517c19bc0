// adroit_sim: the simulation driver as a stand-alone node.
#include <ros/ros.h>

#include <cstdio>

#include "robot_driver.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "adroit_sim");
  std::unique_ptr<adroit::driver::RobotDriver> driver;
  try {
    driver = adroit::driver::makeSimDriver(ros::NodeHandle(), ros::NodeHandle("~"));
  } catch (const std::exception& e) {
    // One line on stderr (rosconsole prints nothing before the node has started).
    std::fprintf(stderr, "[FATAL] adroit_sim: %s\n", e.what());
    return 1;
  }
  driver->start();
  // Two threads for the default queue, so diagnostics go on during a long /step; the
  // safety path has its own queue and thread inside the driver.
  ros::MultiThreadedSpinner spinner(2);
  spinner.spin();
  driver->stop();
  return 0;
}
