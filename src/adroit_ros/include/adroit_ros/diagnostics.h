// Building a node's diagnostics status, and counting rejected input by reason.
#pragma once

#include <ros/publisher.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include <diagnostic_msgs/DiagnosticStatus.h>

namespace adroit::rosutil {

// One DiagnosticStatus, filled key by key; the level only rises (OK < WARN < ERROR), the
// message of the highest level raised first stays.
class StatusBuilder {
 public:
  StatusBuilder(const std::string& name, const std::string& hardware_id);

  void add(const std::string& key, const std::string& value);
  void add(const std::string& key, const char* value) { add(key, std::string(value)); }
  void add(const std::string& key, bool value) { add(key, std::string(value ? "true" : "false")); }
  void add(const std::string& key, double value);
  template <typename Int, typename = std::enable_if_t<std::is_integral_v<Int> && !std::is_same_v<Int, bool>>>
  void add(const std::string& key, Int value) {
    add(key, std::to_string(value));
  }

  void raise(std::uint8_t level, const std::string& message);  // diagnostic_msgs levels
  const diagnostic_msgs::DiagnosticStatus& status() const { return status_; }
  // Publishes it as a DiagnosticArray stamped now.
  void publish(const ros::Publisher& publisher) const;

 private:
  diagnostic_msgs::DiagnosticStatus status_;
  bool message_set_ = false;
};

// How many inputs were rejected, per reason. The reasons are fixed at construction, so
// counting allocates nothing and takes no lock: any thread (a 500 Hz loop included) may count.
class RejectionCounters {
 public:
  explicit RejectionCounters(std::vector<std::string> reasons);

  void count(std::size_t reason) { counts_[reason].fetch_add(1, std::memory_order_relaxed); }
  std::uint64_t get(std::size_t reason) const { return counts_[reason].load(std::memory_order_relaxed); }
  std::uint64_t total() const;
  std::size_t size() const { return reasons_.size(); }
  const std::string& reason(std::size_t i) const { return reasons_[i]; }
  // Adds "<prefix>_total" and "<prefix>_<reason>" for every reason.
  void addTo(StatusBuilder& status, const std::string& prefix) const;

 private:
  std::vector<std::string> reasons_;
  std::unique_ptr<std::atomic<std::uint64_t>[]> counts_;
};

}  // namespace adroit::rosutil
