#include "adroit_mpc/fd_derivatives.h"

#include <stdexcept>
#include <string>

namespace adroit_mpc {

void setKnotState(const mjModel* m, mjData* d, const Eigen::VectorXd& state, const Eigen::VectorXd& ctrl,
                  double time) {
  mju_copy(d->qpos, state.data(), m->nq);
  mju_copy(d->qvel, state.data() + m->nq, m->nv);
  if (m->na) mju_copy(d->act, state.data() + m->nq + m->nv, m->na);
  mju_copy(d->ctrl, ctrl.data(), m->nu);
  mju_zero(d->qacc_warmstart, m->nv);  // cold, as in rollout(): independent of the worker's history
  d->time = time;
}

void FdDerivatives::initialize(const mjModel* m, int horizon, int workers, const FdSettings& settings) {
  if (!(settings.epsilon > 0)) throw std::invalid_argument("fd derivatives: epsilon must be positive");
  if (settings.skip < 1) throw std::invalid_argument("fd derivatives: derivative_skip must be >= 1, got " +
                                                      std::to_string(settings.skip));
  if (horizon < 1) throw std::invalid_argument("fd derivatives: horizon must be >= 1 knot");
  if (workers < 1) throw std::invalid_argument("fd derivatives: need at least one worker");
  model_ = m;
  settings_ = settings;
  horizon_ = horizon;
  nx_ = 2 * m->nv + m->na;
  computed_.clear();
  for (int t = 0; t < horizon; t += settings.skip) computed_.push_back(t);
  if (computed_.back() != horizon - 1) computed_.push_back(horizon - 1);
  data_.clear();
  A_rows_.clear();
  B_rows_.clear();
  for (int w = 0; w < workers; ++w) {
    data_.push_back(adroit::makeData(m));
    A_rows_.emplace_back(nx_, nx_);
    B_rows_.emplace_back(nx_, m->nu);
  }
}

void FdDerivatives::compute(adroit::ThreadPool& pool, const std::vector<Eigen::VectorXd>& states,
                            const std::vector<Eigen::VectorXd>& ctrl, const std::vector<double>& times,
                            std::vector<Eigen::MatrixXd>& A, std::vector<Eigen::MatrixXd>& B) {
  const mjModel* m = model_;
  pool.parallelForWorkers(computed_.size(), [&](std::size_t i, std::size_t w) {
    const int t = computed_[i];
    mjData* d = data_[w].get();
    setKnotState(m, d, states[t], ctrl[t], times[t]);
    mjd_transitionFD(m, d, settings_.epsilon, settings_.centered, A_rows_[w].data(), B_rows_[w].data(),
                     nullptr, nullptr);
    A[t] = A_rows_[w];
    B[t] = B_rows_[w];
  });
  // Hold each computed linearisation over the skipped knots after it.
  for (std::size_t i = 0; i < computed_.size(); ++i) {
    const int from = computed_[i];
    const int until = i + 1 < computed_.size() ? computed_[i + 1] : horizon_;
    for (int t = from + 1; t < until; ++t) {
      A[t] = A[from];
      B[t] = B[from];
    }
  }
}

}  // namespace adroit_mpc
