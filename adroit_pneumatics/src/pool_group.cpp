#include "adroit_pneumatics/pool_group.h"

#include <algorithm>
#include <stdexcept>

namespace adroit::pneumatics {

namespace {

// The model every pool of the group shares (their known names), checked before use.
const std::vector<std::string>& sharedModel(const std::vector<std::unique_ptr<CylinderPool>>& pools) {
  if (pools.empty()) throw std::invalid_argument("pool group has no pools");
  for (const auto& p : pools) {
    if (!p) throw std::invalid_argument("pool group: null pool");
    if (p->knownNames() != pools.front()->knownNames())
      throw std::invalid_argument("the pools of a group must share one model (their known cylinder names differ)");
  }
  return pools.front()->knownNames();
}

}  // namespace

PoolGroup::PoolGroup(std::vector<std::unique_ptr<CylinderPool>> pools)
    : pools_(std::move(pools)), state_columns_(sharedModel(pools_)), reference_columns_(sharedModel(pools_)) {
  std::vector<int> owner(pools_.front()->knownNames().size(), -1);
  for (std::size_t k = 0; k < pools_.size(); ++k) {
    for (const auto& n : pools_[k]->names()) {
      const int known = state_columns_.find(n);  // every pool checked its names against the model
      if (owner[known] >= 0)
        throw std::invalid_argument("cylinder '" + n + "' is in pool " + std::to_string(owner[known]) + " and pool " +
                                    std::to_string(k) + " of the group");
      owner[known] = static_cast<int>(k);
      names_.push_back(n);
    }
  }
  reference_verdicts_.resize(pools_.size());
  state_verdicts_.resize(pools_.size());
  commands_.assign(names_.size(), 0.0);
}

const std::vector<Verdict>& PoolGroup::setReference(double now, double t0, double dt, std::size_t steps,
                                                    const std::vector<std::string>& names,
                                                    const std::vector<double>& force) {
  const Columns& columns = reference_columns_.resolve(names);
  for (std::size_t k = 0; k < pools_.size(); ++k)
    reference_verdicts_[k] = pools_[k]->setResolvedReference(now, t0, dt, steps, columns, force);
  return reference_verdicts_;
}

const std::vector<StateVerdict>& PoolGroup::setState(double now, double stamp, const std::vector<std::string>& names,
                                                     const std::vector<double>& pressure,
                                                     const std::vector<double>& length,
                                                     const std::vector<double>& length_rate, double supply) {
  const Columns& columns = names.empty() ? state_columns_.modelOrder() : state_columns_.resolve(names);
  for (std::size_t k = 0; k < pools_.size(); ++k)
    state_verdicts_[k] = pools_[k]->setResolvedState(now, stamp, columns, pressure, length, length_rate, supply);
  return state_verdicts_;
}

const std::vector<double>& PoolGroup::update(double now) {
  auto out = commands_.begin();
  for (auto& pool : pools_) {
    const std::vector<double>& u = pool->update(now);
    out = std::copy(u.begin(), u.end(), out);
  }
  return commands_;
}

bool PoolGroup::valveIndicesResolved() const {
  return std::all_of(pools_.begin(), pools_.end(), [](const auto& p) { return p->valveIndicesResolved(); });
}

std::vector<int> PoolGroup::valveIndices() const {
  std::vector<int> out;
  for (const auto& p : pools_) out.insert(out.end(), p->valveIndices().begin(), p->valveIndices().end());
  return out;
}

void PoolGroup::recordPolicyLag(double seconds) {
  for (auto& p : pools_) p->recordPolicyLag(seconds);
}

}  // namespace adroit::pneumatics
