#include "adroit_core/box_qp.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace adroit {

namespace {

void checkSize(const char* what, Eigen::Index size, int n) {
  if (size != n)
    throw std::invalid_argument(std::string("BoxQp::solve: ") + what + " has size " + std::to_string(size) +
                                ", expected " + std::to_string(n));
}

}  // namespace

BoxQp::BoxQp(int n, BoxQpSettings settings)
    : n_(n),
      settings_(settings),
      free_(Eigen::Array<bool, Eigen::Dynamic, 1>::Constant(n > 0 ? n : 0, true)),
      free_index_(n > 0 ? n : 0),
      H_free_(Eigen::MatrixXd::Zero(n > 0 ? n : 0, n > 0 ? n : 0)),
      grad_(n > 0 ? n : 0),
      Hx_(n > 0 ? n : 0),
      search_(n > 0 ? n : 0),
      candidate_(n > 0 ? n : 0),
      Hcandidate_(n > 0 ? n : 0),
      scratch_(n > 0 ? n : 0) {
  if (n <= 0) throw std::invalid_argument("BoxQp: dimension must be positive, got " + std::to_string(n));
  if (settings.max_iterations < 0 || !(settings.step_decrease > 0 && settings.step_decrease < 1) ||
      !(settings.armijo > 0 && settings.armijo < 1) || !(settings.min_step > 0))
    throw std::invalid_argument(
        "BoxQpSettings: need max_iterations >= 0, step_decrease and armijo in (0, 1), min_step > 0");
}

double BoxQp::objective(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, const Eigen::VectorXd& x,
                        Eigen::VectorXd& Hx) const {
  Hx.noalias() = H * x;
  return 0.5 * x.dot(Hx) + g.dot(x);
}

bool BoxQp::updateFreeSet(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, const Eigen::VectorXd& lower,
                          const Eigen::VectorXd& upper, const Eigen::VectorXd& x, bool force_factor) {
  grad_ = g + Hx_;
  bool changed = force_factor;
  int count = 0;
  for (int i = 0; i < n_; ++i) {
    // Clamped: at a bound with the gradient pushing further out (Tassa 2014, alg. 1).
    const bool clamped = (x[i] == lower[i] && grad_[i] > 0) || (x[i] == upper[i] && grad_[i] < 0);
    if (free_[i] == clamped) changed = true;
    free_[i] = !clamped;
    if (!clamped) free_index_[count++] = i;
  }
  free_count_ = count;
  if (!changed || count == 0) return true;
  for (int j = 0; j < count; ++j)
    for (int i = j; i < count; ++i) H_free_(i, j) = H(free_index_[i], free_index_[j]);
  Eigen::Ref<Eigen::MatrixXd> block(H_free_.topLeftCorner(count, count));
  Eigen::LLT<Eigen::Ref<Eigen::MatrixXd>> llt(block);  // in place: no allocation
  return llt.info() == Eigen::Success;
}

BoxQpStatus BoxQp::solve(const Eigen::MatrixXd& H, const Eigen::VectorXd& g, const Eigen::VectorXd& lower,
                         const Eigen::VectorXd& upper, Eigen::VectorXd& x) {
  if (H.rows() != n_ || H.cols() != n_)
    throw std::invalid_argument("BoxQp::solve: H is " + std::to_string(H.rows()) + "x" + std::to_string(H.cols()) +
                                ", expected " + std::to_string(n_) + "x" + std::to_string(n_));
  checkSize("g", g.size(), n_);
  checkSize("lower", lower.size(), n_);
  checkSize("upper", upper.size(), n_);
  checkSize("x", x.size(), n_);
  for (int i = 0; i < n_; ++i)
    if (!(lower[i] <= upper[i]))
      throw std::invalid_argument("BoxQp::solve: lower[" + std::to_string(i) + "] = " + std::to_string(lower[i]) +
                                  " is not <= upper = " + std::to_string(upper[i]));

  x = x.cwiseMax(lower).cwiseMin(upper);
  if (!x.allFinite()) x = 0.5 * (lower + upper);  // a NaN warm start says nothing
  if (!x.allFinite()) x = Eigen::VectorXd::Zero(n_).cwiseMax(lower).cwiseMin(upper);  // infinite bounds
  double value = objective(H, g, x, Hx_);
  double old_value = value;
  free_.setConstant(true);
  BoxQpStatus status = BoxQpStatus::kMaxIterations;
  for (iterations_ = 0;; ++iterations_) {
    if (!updateFreeSet(H, g, lower, upper, x, iterations_ == 0)) return BoxQpStatus::kHessianNotPositiveDefinite;
    if (free_count_ == 0) {
      status = BoxQpStatus::kAllClamped;
      break;
    }
    if (iterations_ > 0 && old_value - value < settings_.min_relative_improvement * std::abs(old_value)) {
      status = BoxQpStatus::kConverged;
      break;
    }
    // Newton step on the free dimensions: search_f = -H_ff^-1 grad_f, clamped dims stay.
    auto y = scratch_.head(free_count_);
    for (int i = 0; i < free_count_; ++i) y[i] = grad_[free_index_[i]];
    if (y.norm() < settings_.min_gradient) {
      status = BoxQpStatus::kConverged;
      break;
    }
    if (iterations_ >= settings_.max_iterations) break;  // kMaxIterations; free set matches x
    const auto L = H_free_.topLeftCorner(free_count_, free_count_);
    L.triangularView<Eigen::Lower>().solveInPlace(y);
    L.transpose().triangularView<Eigen::Upper>().solveInPlace(y);
    search_.setZero();
    for (int i = 0; i < free_count_; ++i) search_[free_index_[i]] = -y[i];
    const double slope = search_.dot(grad_);  // directional derivative, < 0 for PD H_ff
    // The full Newton step predicts a decrease of -slope / 2: if that is below the relative
    // threshold the box optimum is reached up to rounding (and Armijo would only see noise).
    if (!(slope < 0) || -0.5 * slope < settings_.min_relative_improvement * std::abs(value)) {
      status = BoxQpStatus::kConverged;
      break;
    }
    // Projected backtracking (Armijo on the projected path).
    double step = 1.0, candidate_value = 0;
    bool found = false;
    while (step >= settings_.min_step) {
      candidate_ = (x + step * search_).cwiseMax(lower).cwiseMin(upper);
      candidate_value = objective(H, g, candidate_, Hcandidate_);
      if ((candidate_value - value) / (step * slope) >= settings_.armijo) {
        found = true;
        break;
      }
      step *= settings_.step_decrease;
    }
    if (!found) {
      status = BoxQpStatus::kNoDescent;
      break;
    }
    x = candidate_;
    Hx_.swap(Hcandidate_);  // both members: swapping storage allocates nothing
    old_value = value;
    value = candidate_value;
  }
  return status;
}

void BoxQp::solveFree(const Eigen::MatrixXd& rhs, Eigen::MatrixXd& out) const {
  if (rhs.rows() != n_)
    throw std::invalid_argument("BoxQp::solveFree: rhs has " + std::to_string(rhs.rows()) + " rows, expected " +
                                std::to_string(n_));
  if (&rhs == &out) throw std::invalid_argument("BoxQp::solveFree: out must not be rhs");
  out.resize(n_, rhs.cols());
  const int f = free_count_;
  // Gather the free rows at the top, solve there in place, scatter down (free_index_ is
  // increasing, so moving from the last row up never overwrites a row still to be moved).
  for (int i = 0; i < f; ++i) out.row(i) = rhs.row(free_index_[i]);
  if (f > 0) {
    auto top = out.topRows(f);
    const auto L = H_free_.topLeftCorner(f, f);
    L.triangularView<Eigen::Lower>().solveInPlace(top);
    L.transpose().triangularView<Eigen::Upper>().solveInPlace(top);
  }
  for (int i = f - 1; i >= 0; --i)
    if (free_index_[i] != i) out.row(free_index_[i]) = out.row(i);
  for (int i = 0; i < n_; ++i)
    if (!free_[i]) out.row(i).setZero();
}

}  // namespace adroit
