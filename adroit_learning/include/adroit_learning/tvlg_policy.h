// A trained time-varying linear-Gaussian controller run as a Policy (thesis 8.2): its mean
// action u_t = K_t x_t + k_t, for the T steps it was trained for. The exploration covariance
// stays in the file; executing a policy never explores.
#pragma once
#include <adroit_learning/policy.h>
#include <adroit_learning/policy_file.h>

#include <memory>
#include <string>

namespace adroit {

class TvlgPolicy : public Policy {
 public:
  // `path` names the file in mismatch messages. Copies share the (possibly large) file.
  TvlgPolicy(std::shared_ptr<const PolicyFile> file, std::string path);
  TvlgPolicy(PolicyFile file, std::string path);

  std::string kind() const override { return "tvlg"; }
  int horizon() const override { return file_->controller.horizon(); }
  void start(const Eigen::Ref<const Eigen::VectorXd>&) override {}
  // Allocates nothing. Throws std::invalid_argument for a step outside [0, T) or sizes other
  // than the controller's (mismatch() finds those before a run).
  void action(int t, const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& touch,
              Eigen::Ref<Eigen::VectorXd> u) override;
  // Joints, cylinders, state layout (policyMismatch) and the actions against the task's
  // unlocked cylinders; touch sensors are not part of a TVLG's state.
  std::string mismatch(const std::vector<std::string>& joints, const std::vector<std::string>& cylinders,
                       const std::vector<std::string>& touch, const StateLayout& layout) const override;

  const PolicyFile& file() const { return *file_; }
  const std::string& path() const { return path_; }

 private:
  std::shared_ptr<const PolicyFile> file_;
  std::string path_;
};

}  // namespace adroit
