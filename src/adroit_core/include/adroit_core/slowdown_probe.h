// How fast the machine itself computes, while something else runs: a thread under SCHED_FIFO
// does a fixed piece of work every period and times it against the fastest it ever took. A
// shared virtual machine can run all its threads several times slower for a while (the 2-core
// VMs here: 4-15x for 100-200 ms about every 1.5 s, with nothing else running); then every
// real-time deadline of the stack is as many times harder to meet, which no wake-up lag of a
// bare thread shows. Used by pneumatics_bench (the pools' timing) and, through the
// `machine_slowdown` tool, by the real-time integration tests to tell a machine that slowed
// down from a stack that did.
#pragma once

#include <atomic>
#include <string>
#include <thread>

#include "adroit_core/timing_stats.h"

namespace adroit {

class SlowdownProbe {
 public:
  // priority: the probe's SCHED_FIFO priority (above what it should not see, e.g. 99 to see the
  // machine alone); period in seconds.
  explicit SlowdownProbe(int priority, double period = 0.005);
  ~SlowdownProbe() { stop(); }
  SlowdownProbe(const SlowdownProbe&) = delete;
  SlowdownProbe& operator=(const SlowdownProbe&) = delete;

  void stop();  // joins; slowdowns() is complete after it
  // Slowdowns (work time / fastest work time), one per period; empty if SCHED_FIFO was refused
  // (refusal() says why). Read after stop().
  const SampleStats& slowdowns() const { return slowdowns_; }
  // The longest the probe's thread waited past a period's wake-up (s): a freeze of the machine.
  // Hardly anything in the guest preempts SCHED_FIFO 99, so that long its core ran nothing of
  // ours; a freeze that falls between two ~50 us work samples never shows in slowdowns().
  // Read after stop().
  double longestStall() const { return longest_stall_; }
  std::string refusal() const { return refusal_; }

 private:
  void run(int priority, double period);

  std::atomic<bool> running_{true};
  SampleStats slowdowns_;
  double longest_stall_ = 0;
  std::string refusal_;
  std::thread thread_;
};

// Fraction of the samples above `factor` (0 for none).
double fractionAbove(const SampleStats& samples, double factor);

}  // namespace adroit
