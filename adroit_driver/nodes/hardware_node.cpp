// adroit_hw: the hardware driver (CanRobot over CAN buses) behind the same ROS wrapper as the
// simulation driver, so every node above it runs unchanged on the robot.
#include "robot_driver.h"

int main(int argc, char** argv) {
  return adroit::driver::runDriverNode(argc, argv, "adroit_hw", &adroit::driver::makeHardwareDriver);
}
