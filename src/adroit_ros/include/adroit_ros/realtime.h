// The real-time path of a node through roscpp.
//
// A message reaches a callback through two threads: roscpp's socket poll thread reads it and
// queues the callback, and the thread serving that queue runs it. Both run at normal
// scheduling unless the node says otherwise, and on two busy cores a normal thread waited
// 50-100 ms behind the stack's SCHED_FIFO threads (the driver's simulation, the pools' solves)
// and the MPC's optimiser: the actuator states reached the pools stale, the valve commands
// reached the driver late and its watchdog tripped (mpc_pneumatic.test, 3 of 3 runs on an idle
// 2-core machine before this). Both threads of the safety path therefore run under SCHED_FIFO:
//
//   * startRos() starts roscpp and remembers the threads it started (the socket poll thread,
//     the XML-RPC server, rosout's publisher, the internal callback queue); once a node has
//     read its parameters, fifoRosThreads(priority) puts them under SCHED_FIFO. They sleep in
//     poll() / select() between messages.
//   * FifoCallbackQueue serves the subscriptions of the path on one thread of its own under
//     SCHED_FIFO; it sleeps while its queue is empty. The node's other callbacks (services,
//     diagnostics) stay on the global queue at normal scheduling. Not ros::spin on the global
//     queue: roscpp disables that queue at shutdown, and a SCHED_FIFO thread spinning on it
//     kept the cores from the thread that completes the shutdown.
//
// Priorities (one place): CAN emulator (the robot's boards) 30; hardware driver 20, simulation
// physics 9; the driver's publisher 19, safety queue 18, roscpp threads 17; pools' input queue,
// publisher and roscpp threads 16, glove reader and teleop's input queue and roscpp threads 16
// (light work with deadlines: above the pools' solves), pools' tick 15; the MPC's input queue
// and roscpp threads 12; MPC control loop 10; the trainer's roscpp threads 11 and keep-alive 10
// (realtime pacing).
#pragma once

#include <atomic>
#include <string>
#include <thread>

#include <ros/callback_queue.h>

namespace adroit::rosutil {

// ros::start(), remembering the threads it started. Call after ros::init and before the first
// NodeHandle (which would start roscpp itself); a second call does nothing.
void startRos();

// Puts roscpp's threads (those startRos started) under SCHED_FIFO at `priority`. False, with
// the reason in *error, when roscpp was not started by startRos (e.g. inside a stock nodelet
// manager) or the system does not permit SCHED_FIFO; the threads keep their scheduling then.
bool fifoRosThreads(int priority, std::string* error);

// A callback queue with one thread of its own, under SCHED_FIFO at `priority` when the system
// permits (priority 0: normal scheduling). Subscribe on queue(), then start(); the destructor
// stops and joins the thread.
class FifoCallbackQueue {
 public:
  FifoCallbackQueue() = default;
  ~FifoCallbackQueue() { stop(); }
  FifoCallbackQueue(const FifoCallbackQueue&) = delete;
  FifoCallbackQueue& operator=(const FifoCallbackQueue&) = delete;

  ros::CallbackQueue* queue() { return &queue_; }
  void start(int priority);  // once
  void stop();               // callbacks still queued stay there
  // The thread's SCHED_FIFO priority once it runs: 0 = normal scheduling (asked for, or
  // refused: refusal() says why), -1 = not started yet.
  int priority() const { return effective_priority_.load(); }
  std::string refusal() const;

 private:
  void serve(int priority);

  ros::CallbackQueue queue_;
  std::atomic<bool> running_{false};
  std::atomic<int> effective_priority_{-1};
  std::string refusal_;  // written by the thread before effective_priority_ is set
  std::thread thread_;
};

}  // namespace adroit::rosutil
