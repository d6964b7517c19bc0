// BoxQp against a brute-force solver written here: for a strictly convex QP on a box, the
// minimiser is the one feasible KKT point among the 3^n choices "free / at lower / at upper"
// per dimension, so enumerating them all and keeping the best feasible one is exact.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include "adroit_core/box_qp.h"

namespace {

using adroit::BoxQp;
using adroit::BoxQpStatus;
using Eigen::MatrixXd;
using Eigen::VectorXd;

struct Brute {
  VectorXd x;
  double value = std::numeric_limits<double>::infinity();
};

double objective(const MatrixXd& H, const VectorXd& g, const VectorXd& x) { return 0.5 * x.dot(H * x) + g.dot(x); }

Brute bruteForce(const MatrixXd& H, const VectorXd& g, const VectorXd& lo, const VectorXd& hi) {
  const int n = static_cast<int>(g.size());
  int combinations = 1;
  for (int i = 0; i < n; ++i) combinations *= 3;
  Brute best;
  for (int code = 0; code < combinations; ++code) {
    VectorXd x = VectorXd::Zero(n);
    std::vector<int> free_dims;
    int c = code;
    for (int i = 0; i < n; ++i, c /= 3) {
      if (c % 3 == 0) free_dims.push_back(i);
      if (c % 3 == 1) x[i] = lo[i];
      if (c % 3 == 2) x[i] = hi[i];
    }
    const int f = static_cast<int>(free_dims.size());
    if (f > 0) {
      // H_ff x_f = -(g_f + H_fc x_c), where x_c holds the fixed values and x_f is still 0.
      MatrixXd Hff(f, f);
      VectorXd rhs(f);
      const VectorXd Hx = H * x;
      for (int a = 0; a < f; ++a) {
        rhs[a] = -(g[free_dims[a]] + Hx[free_dims[a]]);
        for (int b = 0; b < f; ++b) Hff(a, b) = H(free_dims[a], free_dims[b]);
      }
      const VectorXd xf = Hff.fullPivLu().solve(rhs);
      for (int a = 0; a < f; ++a) x[free_dims[a]] = xf[a];
    }
    bool feasible = true;
    for (int i = 0; i < n; ++i) feasible = feasible && x[i] >= lo[i] - 1e-12 && x[i] <= hi[i] + 1e-12;
    if (!feasible) continue;
    const double v = objective(H, g, x);
    if (v < best.value) best = {x, v};
  }
  return best;
}

struct RandomQp {
  MatrixXd H;
  VectorXd g, lo, hi;
};

RandomQp randomQp(std::mt19937& rng, int n) {
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> uniform(0.05, 1.0);
  RandomQp p;
  MatrixXd M(n, n);
  for (int i = 0; i < M.size(); ++i) M(i) = normal(rng);
  p.H = M * M.transpose() + 0.05 * MatrixXd::Identity(n, n);
  p.g.resize(n);
  p.lo.resize(n);
  p.hi.resize(n);
  for (int i = 0; i < n; ++i) {
    p.g[i] = 3.0 * normal(rng);  // large against the box: the unconstrained optimum is mostly outside
    p.lo[i] = -uniform(rng);
    p.hi[i] = uniform(rng);
  }
  return p;
}

TEST(BoxQp, MatchesBruteForceOnRandomProblems) {
  std::mt19937 rng(11);
  int with_active_bounds = 0, with_free_dims = 0, total = 0;
  for (int n = 1; n <= 6; ++n) {
    BoxQp qp(n);
    for (int trial = 0; trial < 80; ++trial) {
      const RandomQp p = randomQp(rng, n);
      const Brute expected = bruteForce(p.H, p.g, p.lo, p.hi);
      ASSERT_TRUE(std::isfinite(expected.value));
      VectorXd x = VectorXd::Zero(n);
      const BoxQpStatus status = qp.solve(p.H, p.g, p.lo, p.hi, x);
      ASSERT_GE(static_cast<int>(status), static_cast<int>(BoxQpStatus::kMaxIterations)) << "n " << n << " trial " << trial;
      EXPECT_NEAR(objective(p.H, p.g, x), expected.value, 1e-9 * (1 + std::abs(expected.value)));
      EXPECT_LT((x - expected.x).cwiseAbs().maxCoeff(), 1e-6) << "n " << n << " trial " << trial;
      EXPECT_TRUE((x.array() >= p.lo.array()).all() && (x.array() <= p.hi.array()).all());
      // The reported free set is the brute force's: clamped exactly where it sits at a bound.
      for (int i = 0; i < n; ++i) {
        const bool at_bound = expected.x[i] == p.lo[i] || expected.x[i] == p.hi[i];
        if (!at_bound) {
          EXPECT_TRUE(qp.free()[i]) << "dim " << i;
        }
      }
      const int active = n - qp.freeCount();
      with_active_bounds += active > 0;
      with_free_dims += qp.freeCount() > 0 && active > 0;
      ++total;
    }
  }
  // The random problems exercise the box: most have active bounds, many mixed sets.
  EXPECT_GT(with_active_bounds, total / 2);
  EXPECT_GT(with_free_dims, total / 5);
}

TEST(BoxQp, WarmStartOutsideTheBoxIsProjectedAndGivesTheSameOptimum) {
  std::mt19937 rng(5);
  BoxQp qp(4);
  for (int trial = 0; trial < 20; ++trial) {
    const RandomQp p = randomQp(rng, 4);
    VectorXd cold = VectorXd::Zero(4);
    VectorXd warm = VectorXd::Constant(4, 50.0);
    qp.solve(p.H, p.g, p.lo, p.hi, cold);
    qp.solve(p.H, p.g, p.lo, p.hi, warm);
    EXPECT_LT((cold - warm).cwiseAbs().maxCoeff(), 1e-7);
  }
}

TEST(BoxQp, InteriorOptimumIsTheNewtonSolution) {
  MatrixXd H(3, 3);
  H << 4, 1, 0, 1, 3, 0.5, 0, 0.5, 2;
  const VectorXd g = (VectorXd(3) << 0.3, -0.2, 0.1).finished();
  BoxQp qp(3);
  VectorXd x = VectorXd::Zero(3);
  EXPECT_EQ(qp.solve(H, g, VectorXd::Constant(3, -10), VectorXd::Constant(3, 10), x), BoxQpStatus::kConverged);
  const VectorXd expected = H.ldlt().solve(-g);
  EXPECT_LT((x - expected).norm(), 1e-12);
  EXPECT_EQ(qp.freeCount(), 3);
}

TEST(BoxQp, EveryDimensionClamped) {
  const MatrixXd H = MatrixXd::Identity(3, 3);
  const VectorXd g = VectorXd::Constant(3, 100.0);  // pushes every x below its lower bound
  BoxQp qp(3);
  VectorXd x = VectorXd::Zero(3);
  EXPECT_EQ(qp.solve(H, g, VectorXd::Constant(3, -1), VectorXd::Constant(3, 1), x), BoxQpStatus::kAllClamped);
  EXPECT_EQ(x, VectorXd::Constant(3, -1));
  EXPECT_EQ(qp.freeCount(), 0);
  MatrixXd out;
  qp.solveFree(MatrixXd::Ones(3, 2), out);
  EXPECT_EQ(out, MatrixXd::Zero(3, 2));
}

TEST(BoxQp, IndefiniteHessianOnTheFreeSetIsReported) {
  MatrixXd H(2, 2);
  H << 1, 0, 0, -1;
  BoxQp qp(2);
  VectorXd x = VectorXd::Zero(2);
  EXPECT_EQ(qp.solve(H, VectorXd::Zero(2), VectorXd::Constant(2, -1), VectorXd::Constant(2, 1), x),
            BoxQpStatus::kHessianNotPositiveDefinite);
}

TEST(BoxQp, SolveFreeInvertsTheFreeBlockAndZeroesClampedRows) {
  std::mt19937 rng(3);
  std::normal_distribution<double> normal;
  BoxQp qp(5);
  int checked = 0;
  for (int trial = 0; trial < 30; ++trial) {
    const RandomQp p = randomQp(rng, 5);
    VectorXd x = VectorXd::Zero(5);
    qp.solve(p.H, p.g, p.lo, p.hi, x);
    const int f = qp.freeCount();
    if (f == 0 || f == 5) continue;
    MatrixXd rhs(5, 4);
    for (int i = 0; i < rhs.size(); ++i) rhs(i) = normal(rng);
    MatrixXd out;
    qp.solveFree(rhs, out);
    std::vector<int> idx;
    for (int i = 0; i < 5; ++i)
      if (qp.free()[i]) idx.push_back(i);
    MatrixXd Hff(f, f), rf(f, 4);
    for (int a = 0; a < f; ++a) {
      rf.row(a) = rhs.row(idx[a]);
      for (int b = 0; b < f; ++b) Hff(a, b) = p.H(idx[a], idx[b]);
    }
    const MatrixXd yf = Hff.fullPivLu().solve(rf);
    for (int a = 0; a < f; ++a) EXPECT_LT((out.row(idx[a]) - yf.row(a)).norm(), 1e-9 * (1 + yf.norm()));
    for (int i = 0; i < 5; ++i)
      if (!qp.free()[i]) {
        EXPECT_EQ(out.row(i).norm(), 0.0);
      }
    ++checked;
  }
  EXPECT_GT(checked, 5);
}

TEST(BoxQp, BadInputThrows) {
  BoxQp qp(2);
  VectorXd x = VectorXd::Zero(2);
  const MatrixXd H = MatrixXd::Identity(2, 2);
  EXPECT_THROW(qp.solve(MatrixXd::Identity(3, 3), VectorXd::Zero(2), -VectorXd::Ones(2), VectorXd::Ones(2), x),
               std::invalid_argument);
  EXPECT_THROW(qp.solve(H, VectorXd::Zero(3), -VectorXd::Ones(2), VectorXd::Ones(2), x), std::invalid_argument);
  EXPECT_THROW(qp.solve(H, VectorXd::Zero(2), VectorXd::Ones(2), -VectorXd::Ones(2), x), std::invalid_argument);
  EXPECT_THROW(BoxQp(0), std::invalid_argument);
  MatrixXd out;
  EXPECT_THROW(qp.solveFree(MatrixXd::Zero(3, 1), out), std::invalid_argument);
}

}  // namespace
