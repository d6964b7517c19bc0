#include "adroit_learning/tvlg_policy.h"

#include <stdexcept>
#include <utility>

namespace adroit {

TvlgPolicy::TvlgPolicy(std::shared_ptr<const PolicyFile> file, std::string path)
    : file_(std::move(file)), path_(std::move(path)) {
  if (!file_) throw std::invalid_argument("TvlgPolicy: no policy file");
}

TvlgPolicy::TvlgPolicy(PolicyFile file, std::string path)
    : TvlgPolicy(std::make_shared<const PolicyFile>(std::move(file)), std::move(path)) {}

void TvlgPolicy::action(int t, const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>&,
                        Eigen::Ref<Eigen::VectorXd> u) {
  const LgController& c = file_->controller;
  // Cheap checks: a wrong size would otherwise write past u in a release build.
  if (t < 0 || t >= c.horizon() || x.size() != c.nx() || u.size() != c.nu())
    throw std::invalid_argument(path_ + ": step " + std::to_string(t) + " with state " + std::to_string(x.size()) +
                                " and action " + std::to_string(u.size()) + ", the policy has T " +
                                std::to_string(c.horizon()) + ", nx " + std::to_string(c.nx()) + ", nu " +
                                std::to_string(c.nu()));
  // The same products as LgController::action without the noise term, so the mean action is
  // bit for bit the trainer's with zero noise.
  u = c.k[t];
  u.noalias() += c.K[t] * x;
}

std::string TvlgPolicy::mismatch(const std::vector<std::string>& joints, const std::vector<std::string>& cylinders,
                                 const std::vector<std::string>&, const StateLayout& layout) const {
  const std::string different = policyMismatch(*file_, path_, joints, cylinders, layout.describe());
  if (!different.empty()) return different;
  std::vector<std::string> actions;
  for (int c : layout.action_cylinders) actions.push_back(layout.cylinder_names[c]);
  if (file_->actions != actions)
    return path_ + ": acts on " + std::to_string(file_->actions.size()) +
           " cylinders, the task unlocks another set of " + std::to_string(actions.size());
  if (file_->controller.nx() != layout.nx())
    return path_ + ": state size " + std::to_string(file_->controller.nx()) + ", the task on this robot gives " +
           std::to_string(layout.nx());
  return "";
}

}  // namespace adroit
