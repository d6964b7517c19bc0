#include "trial.h"

#include <adroit_mpc/task_params.h>

#include <random>

using namespace adroit_mpc;

namespace success {

std::string sceneOf(const std::string& task) {
  return task == "catch" ? "bottle" : task == "relocate" ? "ball" : "keypad";
}

std::vector<TrialSpec> makeTrials(const std::string& task, int n, unsigned seed, const success::World& world) {
  const double side = world.drop_offset, height = world.drop_center, spread = world.drop_half;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  const TaskParams defaults = defaultTaskParams(task);
  std::vector<TrialSpec> trials(n);
  for (int i = 0; i < n; ++i) {
    TrialSpec& s = trials[i];
    s.index = i;
    if (task == "catch") {
      const Eigen::Vector3d goal = paramVector3(task, defaults, "goal_position");
      s.goal = goal;
      s.object_start = goal + Eigen::Vector3d(side * u(rng), side * u(rng), height + spread * u(rng));
    } else if (task == "relocate") {
      const Eigen::Vector3d hold = paramVector3(task, defaults, "hold_position");
      s.object_start = hold + Eigen::Vector3d(side * u(rng), side * u(rng), height + spread * u(rng));
      Eigen::Vector3d offset;
      do {  // beyond the success radius of the hold by at least 2 cm
        offset = Eigen::Vector3d(0.08 * u(rng), 0.06 * u(rng), -0.05 + 0.05 * u(rng));
      } while (offset.norm() < kRelocateMinDistance);
      s.goal = hold + offset;
    } else {
      std::uniform_int_distribution<int> digit(0, static_cast<int>(world.key_set.size()) - 1);
      for (int k = 0; k < world.keys; ++k) s.keys.push_back(world.key_set[digit(rng)]);
    }
  }
  return trials;
}

const std::map<std::string, Variant>& knownVariants() {
  static const std::map<std::string, Variant> known = {
      {"ilqg", {"ilqg", "ilqg", true}},
      {"sampling", {"sampling", "sampling", true}},
      {"cem", {"cem", "cem", true}},
      {"cem_pneumatic", {"cem_pneumatic", "cem", true, true}},
      {"nosyn", {"nosyn", "ilqg", false}},
      {"pneumatic", {"pneumatic", "ilqg", true, true}},
      {"pneumatic_open", {"pneumatic_open", "ilqg", true, true, true}},
      {"as_planned", {"as_planned", "ilqg", true, false, false, true}},
      {"nocomp", {"nocomp", "ilqg", true, false, false, false, false}},
      {"coldfd", {"coldfd", "ilqg", true, false, false, false, true, false}},
      {"fullfd", {"fullfd", "ilqg", true, false, false, false, true, true, false}},
      {"pneumatic_fullfd", {"pneumatic_fullfd", "ilqg", true, true, false, false, true, true, false}}};
  return known;
}

}  // namespace success
