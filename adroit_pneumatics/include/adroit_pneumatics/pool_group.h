// Several CylinderPools driven as one: one input path that resolves each message's names
// once for all of them, one tick that runs every pool in turn, and one command carrying
// every cylinder of the group. Each pool keeps its own cylinders, options, verdicts,
// counters and statistics, as when it runs alone. ROS-free; the pool node and nodelet
// wrap a group (of one, for a single pool).
//
// Why: six pools, each with its own input thread, 200 Hz tick thread and publisher thread,
// woke the machine about 3 x 6 x 200 times a second plus six deliveries of every state and
// reference, and sent the driver six valve commands per tick (README "Pool group").
//
// Threads as CylinderPool: setState/setReference on one input thread, update on one tick
// thread (allocates nothing and never waits: test_pool_realtime), the rest on any thread.
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "adroit_pneumatics/pool.h"

namespace adroit::pneumatics {

class PoolGroup {
 public:
  // Throws std::invalid_argument for no pools, pools of different models (known names),
  // or a cylinder in two pools: the group's command names every cylinder once (the driver
  // rejects, whole, a command that names one twice).
  explicit PoolGroup(std::vector<std::unique_ptr<CylinderPool>> pools);

  std::size_t size() const { return pools_.size(); }
  CylinderPool& pool(std::size_t k) { return *pools_[k]; }
  const CylinderPool& pool(std::size_t k) const { return *pools_[k]; }
  // Every cylinder of the group, pool by pool (each pool's names() order): the command order.
  const std::vector<std::string>& names() const { return names_; }

  // --- input thread: one verdict per pool (pool order), valid until the next call -------
  const std::vector<Verdict>& setReference(double now, double t0, double dt, std::size_t steps,
                                           const std::vector<std::string>& names, const std::vector<double>& force);
  const std::vector<StateVerdict>& setState(double now, double stamp, const std::vector<std::string>& names,
                                            const std::vector<double>& pressure, const std::vector<double>& length,
                                            const std::vector<double>& length_rate, double supply);

  // --- tick thread: every pool's update(now) in turn; commands in names() order ---------
  const std::vector<double>& update(double now);

  // --- any thread -------------------------------------------------------------------------
  // Every pool has its valve indices (CylinderPool::valveIndicesResolved): the group's
  // command can go by index. valveIndices() is then names() order.
  bool valveIndicesResolved() const;
  std::vector<int> valveIndices() const;
  void recordPolicyLag(double seconds);  // one command carries every pool's cylinders

 private:
  std::vector<std::unique_ptr<CylinderPool>> pools_;
  std::vector<std::string> names_;
  NameColumns state_columns_, reference_columns_;  // resolved once per message for every pool
  std::vector<Verdict> reference_verdicts_;
  std::vector<StateVerdict> state_verdicts_;
  std::vector<double> commands_;  // sized at construction
};

}  // namespace adroit::pneumatics
