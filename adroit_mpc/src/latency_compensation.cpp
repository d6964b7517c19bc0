#include <adroit_mpc/latency_compensation.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

namespace adroit_mpc {

void StatePredictor::initialize(const mjModel* model) {
  model_ = model;
  data_ = adroit::makeData(model);
}

double StatePredictor::predict(const PlanPolicy& policy, double feedback_scale, double seconds, PlannerState& state) {
  if (!model_) throw std::logic_error("StatePredictor::predict before initialize()");
  const mjModel* m = model_;
  if (policy.policy.knots() == 0) return 0;
  // No further than the running policy's last knot: it says nothing beyond (a latency that
  // long leaves the MPC nothing to compensate with).
  const double last = policy.policy.t0 + (policy.policy.knots() - 1) * policy.policy.dt;
  const int knots = std::min(static_cast<int>(std::lround(seconds / m->opt.timestep)),
                             static_cast<int>(std::floor((last - state.time) / m->opt.timestep + 1e-6)));
  if (knots <= 0) return 0;
  mjData* d = data_.get();
  d->time = state.time;
  mju_copy(d->qpos, state.qpos.data(), m->nq);
  mju_copy(d->qvel, state.qvel.data(), m->nv);
  if (m->na) mju_copy(d->act, state.act.data(), m->na);
  mju_zero(d->qacc_warmstart, m->nv);  // as a rollout starts: independent of the last prediction
  // MuJoCo answers a non-finite control by zeroing it and a non-finite state by resetting the
  // data to the model's defaults, counting a warning: a prediction that did either is
  // discarded (the robot would not have done that), as is one that ends non-finite.
  constexpr std::array<int, 4> kDiverged = {mjWARN_BADCTRL, mjWARN_BADQPOS, mjWARN_BADQVEL, mjWARN_BADQACC};
  std::array<int, 4> warnings{};
  for (std::size_t i = 0; i < kDiverged.size(); ++i) warnings[i] = d->warning[kDiverged[i]].number;
  for (int k = 0; k < knots; ++k) {
    policy.action(d->time, d->qpos, d->qvel, d->act, d->ctrl, feedback_scale);
    mj_step(m, d);
  }
  for (std::size_t i = 0; i < kDiverged.size(); ++i)
    if (d->warning[kDiverged[i]].number != warnings[i]) return 0;
  const auto finite = [](const mjtNum* v, int n) { return std::all_of(v, v + n, [](mjtNum x) { return std::isfinite(x); }); };
  if (!finite(d->qpos, m->nq) || !finite(d->qvel, m->nv) || !finite(d->act, m->na)) return 0;
  std::copy(d->qpos, d->qpos + m->nq, state.qpos.begin());
  std::copy(d->qvel, d->qvel + m->nv, state.qvel.begin());
  std::copy(d->act, d->act + m->na, state.act.begin());
  const double advanced = knots * m->opt.timestep;
  state.time += advanced;
  return advanced;
}

void LatencyEstimate::record(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return;
  recent_[count_ % kWindow] = seconds;
  ++count_;
}

double LatencyEstimate::expected() const {
  const std::size_t n = std::min(count_, kWindow);
  if (n == 0) return 0;
  std::array<double, kWindow> sorted = recent_;
  std::nth_element(sorted.begin(), sorted.begin() + n / 2, sorted.begin() + n);
  return sorted[n / 2];
}

}  // namespace adroit_mpc
