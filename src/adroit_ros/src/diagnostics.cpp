#include "adroit_ros/diagnostics.h"

#include <ros/time.h>

#include <sstream>

#include <diagnostic_msgs/DiagnosticArray.h>

namespace adroit::rosutil {

StatusBuilder::StatusBuilder(const std::string& name, const std::string& hardware_id) {
  status_.name = name;
  status_.hardware_id = hardware_id;
  status_.level = diagnostic_msgs::DiagnosticStatus::OK;
}

void StatusBuilder::add(const std::string& key, const std::string& value) {
  diagnostic_msgs::KeyValue kv;
  kv.key = key;
  kv.value = value;
  status_.values.push_back(std::move(kv));
}

void StatusBuilder::add(const std::string& key, double value) {
  std::ostringstream o;
  o << value;
  add(key, o.str());
}

void StatusBuilder::raise(std::uint8_t level, const std::string& message) {
  if (message_set_ && level <= status_.level) return;
  status_.level = level;
  status_.message = message;
  message_set_ = true;
}

void StatusBuilder::publish(const ros::Publisher& publisher) const {
  diagnostic_msgs::DiagnosticArray array;
  array.header.stamp = ros::Time::now();
  array.status.push_back(status_);
  publisher.publish(array);
}

RejectionCounters::RejectionCounters(std::vector<std::string> reasons)
    : reasons_(std::move(reasons)), counts_(new std::atomic<std::uint64_t>[reasons_.size()]) {
  for (std::size_t i = 0; i < reasons_.size(); ++i) counts_[i] = 0;
}

std::uint64_t RejectionCounters::total() const {
  std::uint64_t sum = 0;
  for (std::size_t i = 0; i < reasons_.size(); ++i) sum += get(i);
  return sum;
}

void RejectionCounters::addTo(StatusBuilder& status, const std::string& prefix) const {
  status.add(prefix + "_total", total());
  for (std::size_t i = 0; i < reasons_.size(); ++i) status.add(prefix + "_" + reasons_[i], get(i));
}

}  // namespace adroit::rosutil
