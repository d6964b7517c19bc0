// No heap allocation in optimize() after the first call, nor in PlanPolicy::action or in
// copying the policy out (same sizes), on the real hand planning model with synergies.
// Counted by replacing malloc, calloc and realloc (Eigen allocates through malloc, which a
// count of operator new alone missed) and the global operator new. AddressSanitizer owns
// malloc: under it only operator new is counted.
#include <adroit_description/scenes.h>
#include <adroit_mpc/cem_planner.h>
#include <adroit_mpc/ilqg_planner.h>
#include <adroit_mpc/planning_model.h>
#include <adroit_mpc/sampling_planner.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

static std::atomic<bool> counting{false};
static std::atomic<long> allocations{0};

#if !defined(__SANITIZE_ADDRESS__)
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* malloc(std::size_t size) {
  if (counting) allocations++;
  return __libc_malloc(size);
}
void* calloc(std::size_t n, std::size_t size) {
  if (counting) allocations++;
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t size) {
  if (counting) allocations++;
  return __libc_realloc(p, size);
}
}
static constexpr bool kMallocCounted = true;
#else
static constexpr bool kMallocCounted = false;
#endif

void* operator new(std::size_t size) {
  if (counting && !kMallocCounted) allocations++;
  if (void* p = std::malloc(size ? size : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t size) { return operator new(size); }
// Not inlined: GCC would then see malloc's memory freed through a "delete" and warn.
[[gnu::noinline]] void operator delete(void* p) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete[](void* p) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete(void* p, std::size_t) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

using namespace adroit_mpc;

namespace {

// Joint angles towards a half-closed hand: a task with real derivatives, no model names.
class PoseTask : public Task {
 public:
  std::string name() const override { return "pose"; }
  std::unique_ptr<Task> clone() const override { return std::make_unique<PoseTask>(*this); }
  void copyParametersFrom(const Task&) override {}
  void bind(const mjModel* m, int) override { nq_ = m->nq; nv_ = m->nv; }
  std::unique_ptr<TaskScratch> makeScratch(const mjModel*) const override { return std::make_unique<TaskScratch>(); }
  double runningCost(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double t, TaskScratch& s) const override {
    return terminalCost(m, d, t, s) + 1e-4 * u.squaredNorm();
  }
  double terminalCost(const mjModel*, const mjData* d, double, TaskScratch&) const override {
    double c = 0;
    for (int i = 0; i < nq_; ++i) c += (d->qpos[i] - 0.5) * (d->qpos[i] - 0.5);
    return c;
  }
  double runningCostDerivatives(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double t, TaskScratch& s,
                                CostDerivatives& out) const override {
    const double c = terminalCostDerivatives(m, d, t, s, out);
    out.lu = 2e-4 * u;
    out.luu.diagonal().setConstant(2e-4);
    return c + 1e-4 * u.squaredNorm();
  }
  double terminalCostDerivatives(const mjModel* m, const mjData* d, double t, TaskScratch& s,
                                 CostDerivatives& out) const override {
    out.setZero();
    for (int i = 0; i < nv_; ++i) {
      out.lx[i] = 2 * (d->qpos[i] - 0.5);
      out.lxx(i, i) = 2;
    }
    return terminalCost(m, d, t, s);
  }
  std::vector<std::string> weightNames() const override { return {}; }
  double weight(const std::string&) const override { return 0; }
  void setWeight(const std::string&, double) override {}
  double error(const mjModel*, const mjData*) const override { return 0; }

 private:
  int nq_ = 0, nv_ = 0;
};

void checkNoAllocation(Planner& planner) {
  PlanningModelSettings model_settings;
  model_settings.timestep = 0.005;
  auto m = loadPlanningModel(adroit::description::sceneFile(descriptionShareDir(), "hand", true), model_settings);
  ASSERT_EQ(m->nq, m->nv);  // the hand scene has hinges only (PoseTask's assumption)
  PlannerSettings s;
  s.horizon = 0.05;  // 10 knots: enough to exercise every phase
  s.dt = 0.005;
  s.threads = 2;
  s.synergies = true;
  s.derivative_skip = 2;
  s.samples = 6;
  s.cem_elites = 3;
  PoseTask task;
  planner.initialize(m.get(), task, s);
  PlannerState state;
  state.qpos.assign(m->qpos0, m->qpos0 + m->nq);
  state.qvel.assign(m->nv, 0.0);
  state.act.assign(m->na, 0.0);
  PlanPolicy policy;
  planner.setState(state);
  planner.optimize();  // the first call may allocate (it should not, but it is allowed)
  planner.policy(policy);
  std::vector<double> ctrl(m->nu);

  allocations = 0;
  counting = true;
  for (int i = 0; i < 3; ++i) {
    state.time += 0.01;
    planner.setState(state);
    planner.setTask(task);
    OptimizeReport r = planner.optimize();
    planner.policy(policy);
    policy.action(state.time + 0.002, state.qpos.data(), state.qvel.data(), nullptr, ctrl.data());
    if (r.diverged) break;
  }
  counting = false;
  EXPECT_EQ(allocations.load(), 0) << planner.name();
}

}  // namespace

TEST(PlannerAllocations, IlqgOptimizeAndActionAllocateNothing) {
  IlqgPlanner planner;
  checkNoAllocation(planner);
}

TEST(PlannerAllocations, SamplingOptimizeAndActionAllocateNothing) {
  SamplingPlanner planner;
  checkNoAllocation(planner);
}

TEST(PlannerAllocations, CemOptimizeAndActionAllocateNothing) {
  CemPlanner planner;
  checkNoAllocation(planner);
}
