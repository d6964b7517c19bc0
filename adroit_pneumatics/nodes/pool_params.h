// Parameters of the pool node / nodelet: one pool, or a group of pools run by one node.
//
// Without ~members the node's private namespace holds one pool's settings, as always. With
// ~members: [pool_0, pool_1, ...] the node runs a group: each member's settings are read
// from ~<member>/ over the node's own (which every member inherits: pools.yaml loaded once),
// and the member reports its diagnostics as <node namespace>/<member> (/adroit/pool_0, the
// name of the single pool node it replaces). The thread settings (rate, realtime_priority,
// tick_phase, tick_on_state, diagnostics_period) are the group's alone. Every error is one
// line naming the parameter (rosutil::ParameterError).
#pragma once

#include <string>
#include <vector>

#include <ros/node_handle.h>

#include "adroit_pneumatics/pool.h"

namespace adroit::pneumatics {

struct PoolSpec {
  std::string name;                     // diagnostics status name
  std::vector<PoolCylinder> cylinders;  // in the pool's order
  std::vector<std::string> known;       // every cylinder of the model, model order
  PoolOptions options;
};

struct GroupSpec {
  std::vector<PoolSpec> pools;  // one without ~members
  double rate = 200.0;          // Hz
  double diagnostics_period = 1.0;
  int realtime_priority = 15;  // the tick's; publisher, input queue and roscpp's threads one above (0: normal)
  double tick_phase = 0.0;     // fraction of the period
  bool tick_on_state = false;
};

// pnh: the node's private namespace; node_name: the status name of a single pool. Throws
// rosutil::ParameterError.
GroupSpec readGroupSpec(const ros::NodeHandle& pnh, const std::string& node_name);

}  // namespace adroit::pneumatics
