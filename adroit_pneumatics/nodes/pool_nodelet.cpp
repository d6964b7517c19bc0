// The pool (or a group of pools) as a nodelet, so pools can share a process (and zero-copy
// messages) with the driver. A bad configuration logs one fatal line and leaves this nodelet idle rather than
// taking down the manager and everything else loaded into it.
#include <exception>
#include <memory>

#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>

namespace adroit::pneumatics {

std::shared_ptr<void> startPool(ros::NodeHandle nh, ros::NodeHandle pnh, const std::string& name);  // pool_ros.cpp

class PoolNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    try {
      // Single-threaded handles: the pool's callbacks never run concurrently.
      pool_ = startPool(getNodeHandle(), getPrivateNodeHandle(), getName());
    } catch (const std::exception& e) {
      NODELET_FATAL("%s: %s", getName().c_str(), e.what());
    }
  }
  std::shared_ptr<void> pool_;
};

}  // namespace adroit::pneumatics

PLUGINLIB_EXPORT_CLASS(adroit::pneumatics::PoolNodelet, nodelet::Nodelet)
