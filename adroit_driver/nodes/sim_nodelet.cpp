// The simulation driver as a nodelet: the same RobotDriver class as the adroit_sim node.
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include "robot_driver.h"

namespace adroit::driver {

class SimNodelet : public nodelet::Nodelet {
 public:
  ~SimNodelet() override {
    if (driver_) driver_->stop();
  }

 private:
  void onInit() override {
    try {
      // The multi-threaded handles: a long /step must not hold up diagnostics (the safety
      // path has its own queue and thread inside the driver).
      driver_ = makeSimDriver(getMTNodeHandle(), getMTPrivateNodeHandle());
    } catch (const std::exception& e) {
      // A nodelet cannot exit its manager: report and stay inert.
      NODELET_FATAL("adroit_sim: %s", e.what());
      return;
    }
    driver_->start();
  }
  std::unique_ptr<RobotDriver> driver_;
};

}  // namespace adroit::driver

PLUGINLIB_EXPORT_CLASS(adroit::driver::SimNodelet, nodelet::Nodelet)
