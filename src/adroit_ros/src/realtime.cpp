#include "adroit_ros/realtime.h"

#include <algorithm>
#include <mutex>
#include <vector>

#include <ros/ros.h>

#include "adroit_core/scheduling.h"

namespace adroit::rosutil {

namespace {
std::mutex ros_threads_mutex;
std::vector<int> ros_threads;  // started by startRos
bool ros_started_here = false;
}  // namespace

void startRos() {
  const std::lock_guard<std::mutex> lock(ros_threads_mutex);
  if (ros_started_here || ros::isStarted()) return;
  const std::vector<int> before = threadIds();
  ros::start();
  for (int id : threadIds())
    if (!std::binary_search(before.begin(), before.end(), id)) ros_threads.push_back(id);
  ros_started_here = true;
}

bool fifoRosThreads(int priority, std::string* error) {
  const std::lock_guard<std::mutex> lock(ros_threads_mutex);
  if (!ros_started_here) {
    if (error) *error = "roscpp was not started by adroit::rosutil::startRos (its threads are unknown)";
    return false;
  }
  for (int id : ros_threads) {
    std::string why;
    // A thread that has ended (none of roscpp's do before shutdown) is not a failure.
    if (!enterFifoThread(id, priority, &why) && fifoPriority(id) >= 0) {
      if (error) *error = why;
      return false;
    }
  }
  return true;
}

void FifoCallbackQueue::start(int priority) {
  if (running_.exchange(true)) return;
  thread_ = std::thread(&FifoCallbackQueue::serve, this, priority);
}

void FifoCallbackQueue::stop() {
  running_ = false;
  if (thread_.joinable()) thread_.join();
}

std::string FifoCallbackQueue::refusal() const {
  return effective_priority_.load() < 0 ? std::string() : refusal_;
}

void FifoCallbackQueue::serve(int priority) {
  if (priority > 0 && enterFifo(priority, &refusal_))
    effective_priority_ = priority;
  else
    effective_priority_ = 0;
  // Waits up to 20 ms for a callback, so a stop is seen within that.
  while (running_.load()) queue_.callAvailable(ros::WallDuration(0.02));
}

}  // namespace adroit::rosutil
