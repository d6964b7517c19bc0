// adroit_hw: the hardware driver (CanRobot over CAN buses) behind the same ROS wrapper as the
// simulation driver, so every node above it runs unchanged on the robot.
#include <ros/ros.h>

#include <cstdio>

#include "robot_driver.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "adroit_hw");
  std::unique_ptr<adroit::driver::RobotDriver> driver;
  try {
    driver = adroit::driver::makeHardwareDriver(ros::NodeHandle(), ros::NodeHandle("~"));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "[FATAL] adroit_hw: %s\n", e.what());
    return 1;
  }
  driver->start();
  ros::MultiThreadedSpinner spinner(2);
  spinner.spin();
  driver->stop();
  return 0;
}
