// adroit_sim: the simulation driver as a stand-alone node.
#include "robot_driver.h"

int main(int argc, char** argv) {
  return adroit::driver::runDriverNode(argc, argv, "adroit_sim", &adroit::driver::makeSimDriver);
}
