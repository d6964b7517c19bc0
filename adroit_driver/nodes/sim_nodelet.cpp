// The simulation driver as a nodelet: the same SimDriver class as the adroit_sim node.
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>

#include "adroit_driver/sim_driver.h"

namespace adroit::driver {

class SimNodelet : public nodelet::Nodelet {
 public:
  ~SimNodelet() override {
    if (driver_) driver_->stop();
  }

 private:
  void onInit() override {
    try {
      driver_ = std::make_unique<SimDriver>(getNodeHandle(), getPrivateNodeHandle());
    } catch (const std::exception& e) {
      // A nodelet cannot exit its manager: report and stay inert.
      NODELET_FATAL("adroit_sim: %s", e.what());
      return;
    }
    driver_->start();
  }
  std::unique_ptr<SimDriver> driver_;
};

}  // namespace adroit::driver

PLUGINLIB_EXPORT_CLASS(adroit::driver::SimNodelet, nodelet::Nodelet)
