// BackwardPass on linear-quadratic problems, where everything it computes has an exact
// answer obtained here by other means: the textbook discrete Riccati recursion, the whole
// problem solved as one dense QP in the stacked controls, and brute force over active sets
// for the box-constrained first step. Also: the regularisation schedule, the line search,
// and that run() / BoxQp::solve() / TvlgPolicy::action() allocate nothing after the first call.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <new>
#include <random>
#include <stdexcept>
#include <vector>

#include "adroit_core/box_qp.h"
#include "adroit_core/line_search.h"
#include "adroit_core/lq_backward_pass.h"
#include "adroit_core/tvlg_policy.h"

// --- allocation hook: counts malloc/free/new/delete of the calling thread while enabled.
// Eigen allocates through malloc, so operator new alone would miss it. AddressSanitizer owns
// malloc itself: under it the hook is left out and the allocation test skips.
#if defined(__SANITIZE_ADDRESS__)
#define ADROIT_COUNT_ALLOCATIONS 0
#else
#define ADROIT_COUNT_ALLOCATIONS 1
#endif

namespace {
thread_local bool t_counting = false;
std::atomic<long> g_allocations{0};
inline void countOne() {
  if (t_counting) g_allocations.fetch_add(1, std::memory_order_relaxed);
}
}  // namespace

#if ADROIT_COUNT_ALLOCATIONS
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void __libc_free(void*);
void* malloc(std::size_t n) {
  countOne();
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t size) {
  countOne();
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t n) {
  countOne();
  return __libc_realloc(p, n);
}
void free(void* p) {
  if (p) countOne();
  __libc_free(p);
}
}
void* operator new(std::size_t n) {
  countOne();
  if (void* p = __libc_malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  countOne();
  return __libc_malloc(n ? n : 1);
}
void* operator new[](std::size_t n, const std::nothrow_t& tag) noexcept { return operator new(n, tag); }
void operator delete(void* p) noexcept {
  if (p) countOne();
  __libc_free(p);
}
void operator delete[](void* p) noexcept { operator delete(p); }
void operator delete(void* p, std::size_t) noexcept { operator delete(p); }
void operator delete[](void* p, std::size_t) noexcept { operator delete(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { operator delete(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { operator delete(p); }
#endif

namespace {

using namespace adroit;
using Eigen::MatrixXd;
using Eigen::VectorXd;

class CountAllocations {
 public:
  CountAllocations() {
    g_allocations = 0;
    t_counting = true;
  }
  ~CountAllocations() { t_counting = false; }
  long count() const { return g_allocations; }
};

// --- a random time-varying LQ problem --------------------------------------------------
// x_{t+1} = A_t x_t + B_t u_t;  cost sum_t 0.5 x'Q x + 0.5 u'R u + u'N x + q'x + r'u
//                                 + 0.5 x_T'Qf x_T + qf'x_T.
struct LqProblem {
  int nx, nu, T;
  std::vector<MatrixXd> A, B, Q, R, N;
  std::vector<VectorXd> q, r;
  MatrixXd Qf;
  VectorXd qf, x0;

  double cost(const std::vector<VectorXd>& u) const {
    VectorXd x = x0;
    double J = 0;
    for (int t = 0; t < T; ++t) {
      J += 0.5 * x.dot(Q[t] * x) + 0.5 * u[t].dot(R[t] * u[t]) + u[t].dot(N[t] * x) + q[t].dot(x) + r[t].dot(u[t]);
      x = A[t] * x + B[t] * u[t];
    }
    return J + 0.5 * x.dot(Qf * x) + qf.dot(x);
  }
  std::vector<VectorXd> states(const std::vector<VectorXd>& u) const {
    std::vector<VectorXd> x(T + 1);
    x[0] = x0;
    for (int t = 0; t < T; ++t) x[t + 1] = A[t] * x[t] + B[t] * u[t];
    return x;
  }
};

MatrixXd randn(std::mt19937& rng, int rows, int cols, double scale = 1.0) {
  std::normal_distribution<double> normal(0.0, scale);
  MatrixXd m(rows, cols);
  for (int i = 0; i < m.size(); ++i) m(i) = normal(rng);
  return m;
}

LqProblem randomProblem(std::mt19937& rng, int nx, int nu, int T) {
  LqProblem p{nx, nu, T, {}, {}, {}, {}, {}, {}, {}, {}, {}, {}};
  for (int t = 0; t < T; ++t) {
    p.A.push_back(MatrixXd::Identity(nx, nx) + randn(rng, nx, nx, 0.15));
    p.B.push_back(randn(rng, nx, nu, 0.5));
    // Joint cost Hessian [Q N'; N R] positive definite, with a non-zero cross term.
    const MatrixXd G = randn(rng, nx + nu, nx + nu, 0.5);
    const MatrixXd W = G * G.transpose() + 0.1 * MatrixXd::Identity(nx + nu, nx + nu);
    p.Q.push_back(W.topLeftCorner(nx, nx));
    p.R.push_back(W.bottomRightCorner(nu, nu));
    p.N.push_back(W.bottomLeftCorner(nu, nx));
    p.q.push_back(randn(rng, nx, 1));
    p.r.push_back(randn(rng, nu, 1));
  }
  const MatrixXd G = randn(rng, nx, nx);
  p.Qf = G * G.transpose() + MatrixXd::Identity(nx, nx);
  p.qf = randn(rng, nx, 1);
  p.x0 = randn(rng, nx, 1);
  return p;
}

// Derivatives of the cost along a nominal (x_bar, u_bar): what an iLQG caller fills in.
LqApproximation approximate(const LqProblem& p, const std::vector<VectorXd>& x_bar,
                            const std::vector<VectorXd>& u_bar) {
  LqApproximation lq(p.nx, p.nu, p.T);
  for (int t = 0; t < p.T; ++t) {
    lq.A[t] = p.A[t];
    lq.B[t] = p.B[t];
    lq.lx[t] = p.Q[t] * x_bar[t] + p.N[t].transpose() * u_bar[t] + p.q[t];
    lq.lu[t] = p.R[t] * u_bar[t] + p.N[t] * x_bar[t] + p.r[t];
    lq.lxx[t] = p.Q[t];
    lq.luu[t] = p.R[t];
    lq.lux[t] = p.N[t];
  }
  lq.lx[p.T] = p.Qf * x_bar[p.T] + p.qf;
  lq.lxx[p.T] = p.Qf;
  return lq;
}

std::vector<VectorXd> zeros(int T, int n) { return std::vector<VectorXd>(T, VectorXd::Zero(n)); }

double relativeError(const MatrixXd& a, const MatrixXd& b) { return (a - b).norm() / (1.0 + b.norm()); }

// --- exactness on unconstrained LQ ------------------------------------------------------

TEST(BackwardPass, GainsAndValueEqualTheTextbookRiccatiRecursion) {
  std::mt19937 rng(42);
  const int nx = 6, nu = 3, T = 20;
  const LqProblem p = randomProblem(rng, nx, nu, T);
  const auto u_bar = zeros(T, nu);
  const LqApproximation lq = approximate(p, p.states(u_bar), u_bar);

  BackwardPass pass(nx, nu, T);
  FeedbackGains gains;
  const BackwardPassResult result = pass.run(lq, u_bar, VectorXd(), VectorXd(), 0.0, gains);
  ASSERT_TRUE(result.ok);

  // Textbook form: V_t(x) = 0.5 x'P x + s'x,  S = R + B'PB,  L = N + B'PA,  m = r + B'p,
  // K = -S^-1 L,  k = -S^-1 m,  P <- Q + A'PA - L'S^-1 L,  s <- q + A's - L'S^-1 m.
  MatrixXd P = lq.lxx[T];
  VectorXd s = lq.lx[T];
  for (int t = T - 1; t >= 0; --t) {
    const MatrixXd& A = lq.A[t];
    const MatrixXd& B = lq.B[t];
    const MatrixXd S = lq.luu[t] + B.transpose() * P * B;
    const MatrixXd L = lq.lux[t] + B.transpose() * P * A;
    const VectorXd m = lq.lu[t] + B.transpose() * s;
    const MatrixXd S_inv = S.inverse();
    EXPECT_LT(relativeError(gains.K[t], -S_inv * L), 1e-8) << "t " << t;
    EXPECT_LT(relativeError(gains.k[t], -S_inv * m), 1e-8) << "t " << t;
    EXPECT_LT(relativeError(pass.Quu(t), S), 1e-8) << "t " << t;
    const MatrixXd P_next = lq.lxx[t] + A.transpose() * P * A - L.transpose() * S_inv * L;
    const VectorXd s_next = lq.lx[t] + A.transpose() * s - L.transpose() * S_inv * m;
    P = P_next;
    s = s_next;
    EXPECT_LT(relativeError(pass.Vxx(t), P), 1e-8) << "t " << t;
    EXPECT_LT(relativeError(pass.Vx(t), s), 1e-8) << "t " << t;
  }
}

TEST(BackwardPass, OneFullStepFromAZeroNominalReachesTheDenseQpOptimum) {
  std::mt19937 rng(7);
  const int nx = 6, nu = 3, T = 20;
  const LqProblem p = randomProblem(rng, nx, nu, T);
  const auto u_bar = zeros(T, nu);
  const auto x_bar = p.states(u_bar);
  const LqApproximation lq = approximate(p, x_bar, u_bar);
  BackwardPass pass(nx, nu, T);
  FeedbackGains gains;
  const BackwardPassResult result = pass.run(lq, u_bar, VectorXd(), VectorXd(), 0.0, gains);
  ASSERT_TRUE(result.ok);

  // Forward pass with alpha = 1.
  std::vector<VectorXd> u(T);
  VectorXd x = p.x0;
  for (int t = 0; t < T; ++t) {
    u[t] = u_bar[t] + gains.k[t] + gains.K[t] * (x - x_bar[t]);
    x = p.A[t] * x + p.B[t] * u[t];
  }

  // Dense QP in U = [u_0; ...; u_{T-1}]: X = Sx x0 + Su U stacks x_0..x_T.
  const int nX = (T + 1) * nx, nU = T * nu;
  MatrixXd Sx = MatrixXd::Zero(nX, nx), Su = MatrixXd::Zero(nX, nU);
  Sx.topRows(nx).setIdentity();
  for (int t = 0; t < T; ++t) {
    Sx.middleRows((t + 1) * nx, nx) = p.A[t] * Sx.middleRows(t * nx, nx);
    Su.middleRows((t + 1) * nx, nx) = p.A[t] * Su.middleRows(t * nx, nx);
    Su.block((t + 1) * nx, t * nu, nx, nu) = p.B[t];
  }
  MatrixXd Qb = MatrixXd::Zero(nX, nX), Rb = MatrixXd::Zero(nU, nU), Nb = MatrixXd::Zero(nU, nX);
  VectorXd qb(nX), rb(nU);
  for (int t = 0; t < T; ++t) {
    Qb.block(t * nx, t * nx, nx, nx) = p.Q[t];
    Rb.block(t * nu, t * nu, nu, nu) = p.R[t];
    Nb.block(t * nu, t * nx, nu, nx) = p.N[t];
    qb.segment(t * nx, nx) = p.q[t];
    rb.segment(t * nu, nu) = p.r[t];
  }
  Qb.bottomRightCorner(nx, nx) = p.Qf;
  qb.tail(nx) = p.qf;
  const MatrixXd H = Su.transpose() * Qb * Su + Rb + Nb * Su + Su.transpose() * Nb.transpose();
  const VectorXd X0 = Sx * p.x0;
  const VectorXd h = Su.transpose() * (Qb * X0 + qb) + Nb * X0 + rb;
  const VectorXd U = H.ldlt().solve(-h);
  std::vector<VectorXd> u_opt(T);
  for (int t = 0; t < T; ++t) u_opt[t] = U.segment(t * nu, nu);

  const double J_opt = p.cost(u_opt), J_new = p.cost(u), J_old = p.cost(u_bar);
  EXPECT_LT(std::abs(J_new - J_opt), 1e-9 * (1 + std::abs(J_opt)));
  for (int t = 0; t < T; ++t) EXPECT_LT(relativeError(u[t], u_opt[t]), 1e-8) << "t " << t;
  // On an exact LQ problem the predicted change of the full step is the actual one.
  EXPECT_NEAR(J_new - J_old, result.dV[0] + result.dV[1], 1e-9 * (1 + std::abs(J_old)));
  EXPECT_LT(J_opt, J_old);
}

TEST(BackwardPass, RegularisationEntersAsDeclared) {
  std::mt19937 rng(9);
  const int nx = 5, nu = 2, T = 3;
  const LqProblem p = randomProblem(rng, nx, nu, T);
  const auto u_bar = zeros(T, nu);
  const LqApproximation lq = approximate(p, p.states(u_bar), u_bar);
  const double mu = 0.7;
  // The last step sees V' = terminal cost, so its Q terms are known in closed form.
  const int t = T - 1;
  const MatrixXd& A = lq.A[t];
  const MatrixXd& B = lq.B[t];
  const MatrixXd& P = lq.lxx[T];
  const MatrixXd Quu = lq.luu[t] + B.transpose() * P * B;
  const MatrixXd Qux = lq.lux[t] + B.transpose() * P * A;
  const VectorXd Qu = lq.lu[t] + B.transpose() * lq.lx[T];
  for (RegularizationType type : {RegularizationType::kControl, RegularizationType::kState}) {
    BackwardPassSettings settings;
    settings.regularization = type;
    BackwardPass pass(nx, nu, T, settings);
    FeedbackGains gains;
    ASSERT_TRUE(pass.run(lq, u_bar, VectorXd(), VectorXd(), mu, gains).ok);
    const bool state = type == RegularizationType::kState;
    const MatrixXd Vreg = P + (state ? mu : 0.0) * MatrixXd::Identity(nx, nx);
    const MatrixXd S = lq.luu[t] + B.transpose() * Vreg * B + (state ? 0.0 : mu) * MatrixXd::Identity(nu, nu);
    const MatrixXd L = lq.lux[t] + B.transpose() * Vreg * A;
    EXPECT_LT(relativeError(gains.K[t], -S.inverse() * L), 1e-10);
    EXPECT_LT(relativeError(gains.k[t], -S.inverse() * Qu), 1e-10);
    // The value update stays exact for the (regularised) gains actually used.
    const MatrixXd& K = gains.K[t];
    const MatrixXd Qxx = lq.lxx[t] + A.transpose() * P * A;
    const MatrixXd Vxx = Qxx + K.transpose() * Quu * K + K.transpose() * Qux + Qux.transpose() * K;
    EXPECT_LT(relativeError(pass.Vxx(t), Vxx), 1e-10);
    EXPECT_LT(relativeError(pass.Quu(t), Quu), 1e-10);  // the exact one, without mu
  }
}

// --- box constraints --------------------------------------------------------------------

// Exact minimiser of 0.5 x'Hx + g'x on [lo, hi] by enumerating all 3^n active sets.
VectorXd bruteForceBoxQp(const MatrixXd& H, const VectorXd& g, const VectorXd& lo, const VectorXd& hi) {
  const int n = static_cast<int>(g.size());
  int combinations = 1;
  for (int i = 0; i < n; ++i) combinations *= 3;
  VectorXd best;
  double best_value = std::numeric_limits<double>::infinity();
  for (int code = 0; code < combinations; ++code) {
    VectorXd x = VectorXd::Zero(n);
    std::vector<int> fr;
    for (int i = 0, c = code; i < n; ++i, c /= 3) {
      if (c % 3 == 0) fr.push_back(i);
      if (c % 3 == 1) x[i] = lo[i];
      if (c % 3 == 2) x[i] = hi[i];
    }
    const int f = static_cast<int>(fr.size());
    if (f > 0) {
      MatrixXd Hff(f, f);
      VectorXd rhs(f);
      const VectorXd Hx = H * x;
      for (int a = 0; a < f; ++a) {
        rhs[a] = -(g[fr[a]] + Hx[fr[a]]);
        for (int b = 0; b < f; ++b) Hff(a, b) = H(fr[a], fr[b]);
      }
      const VectorXd xf = Hff.llt().solve(rhs);
      for (int a = 0; a < f; ++a) x[fr[a]] = xf[a];
    }
    if (((x - lo).array() < -1e-12).any() || ((x - hi).array() > 1e-12).any()) continue;
    const double v = 0.5 * x.dot(H * x) + g.dot(x);
    if (v < best_value) {
      best_value = v;
      best = x;
    }
  }
  return best;
}

TEST(BackwardPass, BoundedFirstControlEqualsBruteForceOnTheQFunction) {
  std::mt19937 rng(21);
  const int nx = 4, nu = 4, T = 1;
  int with_clamped = 0;
  for (int trial = 0; trial < 40; ++trial) {
    LqProblem p = randomProblem(rng, nx, nu, T);
    p.r[0] *= 4.0;  // strong linear terms: the unconstrained step leaves the box
    const std::vector<VectorXd> u_bar = {randn(rng, nu, 1, 0.2)};
    const auto x_bar = p.states(u_bar);
    const LqApproximation lq = approximate(p, x_bar, u_bar);
    const VectorXd u_min = VectorXd::Constant(nu, -0.5), u_max = VectorXd::Constant(nu, 0.5);

    BackwardPass pass(nx, nu, T);
    FeedbackGains gains;
    const BackwardPassResult result = pass.run(lq, u_bar, u_min, u_max, 0.0, gains);
    ASSERT_TRUE(result.ok);

    // Q-function of step 0, computed here: V_1 is the terminal cost.
    const MatrixXd& A = lq.A[0];
    const MatrixXd& B = lq.B[0];
    const MatrixXd Quu = lq.luu[0] + B.transpose() * lq.lxx[1] * B;
    const MatrixXd Qux = lq.lux[0] + B.transpose() * lq.lxx[1] * A;
    const VectorXd Qu = lq.lu[0] + B.transpose() * lq.lx[1];
    const VectorXd lo = u_min - u_bar[0], hi = u_max - u_bar[0];
    const VectorXd k_exact = bruteForceBoxQp(Quu, Qu, lo, hi);
    ASSERT_EQ(k_exact.size(), nu);
    EXPECT_LT((gains.k[0] - k_exact).cwiseAbs().maxCoeff(), 1e-7) << "trial " << trial;
    const VectorXd u0 = u_bar[0] + gains.k[0];
    EXPECT_TRUE((u0.array() >= u_min.array() - 1e-12).all() && (u0.array() <= u_max.array() + 1e-12).all());

    // Feedback: zero rows where the optimum sits at a bound, -Quu_ff^-1 Qux_f elsewhere.
    std::vector<int> fr;
    for (int i = 0; i < nu; ++i)
      if (k_exact[i] > lo[i] + 1e-9 && k_exact[i] < hi[i] - 1e-9) fr.push_back(i);
    const int f = static_cast<int>(fr.size());
    with_clamped += f < nu;
    EXPECT_EQ(result.clamped_controls, nu - f);
    MatrixXd Hff(f, f), Rf(f, nx);
    for (int a = 0; a < f; ++a) {
      Rf.row(a) = Qux.row(fr[a]);
      for (int b = 0; b < f; ++b) Hff(a, b) = Quu(fr[a], fr[b]);
    }
    const MatrixXd Kf = f > 0 ? MatrixXd(-Hff.inverse() * Rf) : MatrixXd(0, nx);
    for (int i = 0, a = 0; i < nu; ++i) {
      if (a < f && fr[a] == i)
        EXPECT_LT(relativeError(gains.K[0].row(i), Kf.row(a++)), 1e-8);
      else
        EXPECT_EQ(gains.K[0].row(i).norm(), 0.0);
    }
  }
  EXPECT_GT(with_clamped, 20);  // the bounds bind in most trials
}

TEST(BackwardPass, NonPositiveDefiniteQuuFailsAtThatStep) {
  std::mt19937 rng(4);
  const int nx = 3, nu = 2, T = 10;
  const LqProblem p = randomProblem(rng, nx, nu, T);
  const auto u_bar = zeros(T, nu);
  LqApproximation lq = approximate(p, p.states(u_bar), u_bar);
  lq.B[6].setZero();
  lq.luu[6] = -MatrixXd::Identity(nu, nu);  // Quu(6) = luu(6) < 0
  BackwardPass pass(nx, nu, T);
  FeedbackGains gains;
  for (bool bounded : {false, true}) {
    const VectorXd lo = bounded ? VectorXd::Constant(nu, -1) : VectorXd();
    const VectorXd hi = bounded ? VectorXd::Constant(nu, 1) : VectorXd();
    BackwardPassResult r = pass.run(lq, u_bar, lo, hi, 0.0, gains);
    EXPECT_FALSE(r.ok);
    EXPECT_EQ(r.failed_step, 6);
    // Enough control regularisation makes it positive definite again.
    r = pass.run(lq, u_bar, lo, hi, 2.0, gains);
    EXPECT_TRUE(r.ok);
  }
}

TEST(BackwardPass, BadInputThrows) {
  const int nx = 3, nu = 2, T = 4;
  BackwardPass pass(nx, nu, T);
  FeedbackGains gains;
  LqApproximation lq(nx, nu, T);
  const auto u_bar = zeros(T, nu);
  EXPECT_THROW(pass.run(LqApproximation(nx, nu, T + 1), u_bar, VectorXd(), VectorXd(), 0, gains),
               std::invalid_argument);
  EXPECT_THROW(pass.run(lq, u_bar, VectorXd::Zero(nu), VectorXd(), 0, gains), std::invalid_argument);
  EXPECT_THROW(pass.run(lq, u_bar, VectorXd::Ones(nu), VectorXd::Zero(nu), 0, gains), std::invalid_argument);
  EXPECT_THROW(pass.run(lq, zeros(T - 1, nu), -VectorXd::Ones(nu), VectorXd::Ones(nu), 0, gains),
               std::invalid_argument);
  EXPECT_THROW(pass.run(lq, u_bar, VectorXd(), VectorXd(), -1.0, gains), std::invalid_argument);
  LqApproximation broken = lq;
  broken.B[2] = MatrixXd::Zero(nx, nu + 1);
  EXPECT_THROW(pass.run(broken, u_bar, VectorXd(), VectorXd(), 0, gains), std::invalid_argument);
  EXPECT_THROW(BackwardPass(0, 1, 1), std::invalid_argument);
}

// --- schedule and line search -----------------------------------------------------------

TEST(RegularizationSchedule, FollowsTheLevenbergMarquardtRule) {
  RegularizationSchedule s;  // mu 1e-6, delta 1, delta0 2
  s.increase();              // delta 2, mu 2e-6
  EXPECT_DOUBLE_EQ(s.mu, 2e-6);
  s.increase();  // delta 4, mu 8e-6
  EXPECT_DOUBLE_EQ(s.mu, 8e-6);
  s.decrease();  // delta min(1/2, 4/2) = 0.5, mu 4e-6
  EXPECT_DOUBLE_EQ(s.mu, 4e-6);
  s.decrease();  // delta 0.25, mu 1e-6
  EXPECT_DOUBLE_EQ(s.mu, 1e-6);
  s.decrease();  // delta 0.125, mu 1.25e-7 < mu_min -> 0
  EXPECT_EQ(s.mu, 0.0);
  s.increase();  // delta max(2, 0.25) = 2, mu max(mu_min, 0) = 1e-6
  EXPECT_DOUBLE_EQ(s.mu, 1e-6);
  int steps = 0;
  while (!s.exhausted() && steps < 100) s.increase(), ++steps;
  EXPECT_TRUE(s.exhausted());
  EXPECT_LT(steps, 15);  // growth is super-exponential
}

TEST(LineSearch, AcceptsTheFullStepWhenThePredictionIsExact) {
  const double dV[2] = {-4.0, 1.0};  // J(alpha) = 10 - 4 alpha + alpha^2
  int calls = 0;
  const auto r = backtrackingLineSearch(
      [&](double a) {
        ++calls;
        return 10.0 + a * dV[0] + a * a * dV[1];
      },
      10.0, dV);
  EXPECT_TRUE(r.accepted);
  EXPECT_EQ(r.alpha, 1.0);
  EXPECT_EQ(r.cost, 7.0);
  EXPECT_EQ(calls, 1);
  EXPECT_DOUBLE_EQ(r.reduction_ratio, 1.0);
}

TEST(LineSearch, BacktracksPastNonFiniteAndInsufficientDecrease) {
  const double dV[2] = {-1.0, 0.0};
  // alpha 1: NaN, alpha 0.5: cost increased, alpha 0.25: 0.2 of the prediction (accepted > 0.1).
  const auto r = backtrackingLineSearch(
      [](double a) {
        if (a > 0.75) return std::numeric_limits<double>::quiet_NaN();
        if (a > 0.375) return 5.1;
        return 5.0 - 0.2 * a;
      },
      5.0, dV);
  EXPECT_TRUE(r.accepted);
  EXPECT_EQ(r.alpha, 0.25);
  EXPECT_EQ(r.tries, 3);
  EXPECT_NEAR(r.reduction_ratio, 0.2, 1e-12);
}

TEST(LineSearch, RejectsWhenNothingImprovesAndAcceptsADecreaseWithoutPrediction) {
  const double dV[2] = {-1.0, 0.5};
  LineSearchSettings settings;
  settings.max_steps = 4;
  auto r = backtrackingLineSearch([](double) { return 3.0; }, 2.0, dV, settings);
  EXPECT_FALSE(r.accepted);
  EXPECT_EQ(r.alpha, 0.0);
  EXPECT_EQ(r.tries, 4);
  const double none[2] = {0.0, 0.0};
  r = backtrackingLineSearch([](double) { return 1.999; }, 2.0, none, settings);
  EXPECT_TRUE(r.accepted);
  r = backtrackingLineSearch([](double) { return 2.0; }, 2.0, none, settings);
  EXPECT_FALSE(r.accepted);
}

// --- no allocation after the first call -------------------------------------------------

TEST(Allocations, RunSolveAndActionAllocateNothingAfterTheFirstCall) {
#if !ADROIT_COUNT_ALLOCATIONS
  GTEST_SKIP() << "AddressSanitizer replaces malloc: allocation counting is off in this build";
#else
  {  // the hook sees Eigen's heap (else a zero below would prove nothing)
    CountAllocations counter;
    VectorXd probe = VectorXd::Constant(100, 1.0);
    EXPECT_EQ(probe.sum(), 100.0);
    EXPECT_GT(counter.count(), 0);
  }
  // The MPC's size (nx 60, nu 45) on a short horizon, so the big products run as they would.
  std::mt19937 rng(1);
  const int nx = 60, nu = 45, T = 4;
  const LqProblem p = randomProblem(rng, nx, nu, T);
  std::vector<VectorXd> u_bar(T);
  for (auto& u : u_bar) u = randn(rng, nu, 1, 0.3);
  const LqApproximation lq = approximate(p, p.states(u_bar), u_bar);
  const VectorXd u_min = VectorXd::Constant(nu, -0.5), u_max = VectorXd::Constant(nu, 0.5);
  for (RegularizationType type : {RegularizationType::kControl, RegularizationType::kState}) {
    BackwardPassSettings settings;
    settings.regularization = type;
    BackwardPass pass(nx, nu, T, settings);
    FeedbackGains gains;
    ASSERT_TRUE(pass.run(lq, u_bar, u_min, u_max, 1e-3, gains).ok);  // first call: may size the gains
    ASSERT_TRUE(pass.run(lq, u_bar, VectorXd(), VectorXd(), 1e-3, gains).ok);
    BackwardPassResult bounded, free;
    long count;
    {
      CountAllocations counter;
      bounded = pass.run(lq, u_bar, u_min, u_max, 1e-3, gains);
      free = pass.run(lq, u_bar, VectorXd(), VectorXd(), 1e-3, gains);
      count = counter.count();
    }
    EXPECT_TRUE(bounded.ok && free.ok);
    EXPECT_GT(bounded.clamped_controls, 0);  // the QP path, with clamping, was exercised
    EXPECT_EQ(count, 0);
  }

  const int n = 45;
  BoxQp qp(n);
  const MatrixXd G = randn(rng, n, n);
  const MatrixXd H = G * G.transpose() + MatrixXd::Identity(n, n);
  const VectorXd g = randn(rng, n, 1, 20.0);
  const VectorXd lo = -VectorXd::Ones(n), hi = VectorXd::Ones(n);
  VectorXd x = VectorXd::Zero(n);
  MatrixXd rhs = randn(rng, n, 60), out(n, 60);
  qp.solve(H, g, lo, hi, x);
  qp.solveFree(rhs, out);
  long count;
  {
    CountAllocations counter;
    x.setZero();
    qp.solve(H, g, lo, hi, x);
    qp.solveFree(rhs, out);
    count = counter.count();
  }
  EXPECT_GT(n - qp.freeCount(), 0);
  EXPECT_GT(qp.freeCount(), 0);
  EXPECT_EQ(count, 0);

  TvlgPolicy policy(61, 60, 45, 30);
  policy.dt = 0.01;
  for (int k = 0; k < 30; ++k) {
    policy.u[k] = randn(rng, 45, 1);
    policy.K[k] = randn(rng, 45, 60);
  }
  policy.u_min = -VectorXd::Ones(45);
  policy.u_max = VectorXd::Ones(45);
  const VectorXd dx = randn(rng, 60, 1);
  VectorXd u(45), xn(61);
  {
    CountAllocations counter;
    for (double t = -0.01; t < 0.35; t += 0.0037) {
      policy.action(t, dx, u, 0.5);
      policy.nominalState(t, xn);
    }
    policy.shiftTo(0.1);
    count = counter.count();
  }
  EXPECT_EQ(count, 0);
#endif
}

}  // namespace
