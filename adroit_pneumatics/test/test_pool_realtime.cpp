// The pool's tick allocates nothing after start-up: this binary replaces malloc & co. and
// the global operator new/delete with versions that count calls made by a thread while
// its thread_local flag is set, and runs thousands of ticks (CylinderPool::update or
// PoolGroup::update + the hand-over of the commands into the publisher's slot) with states
// and references fed in between, asserting that the tick thread made no allocation and
// freed nothing.
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <new>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "adroit_pneumatics/plant.h"
#include "adroit_pneumatics/pool.h"
#include "adroit_pneumatics/pool_group.h"

// --- the allocation hook ----------------------------------------------------------------
namespace {
thread_local bool t_counting = false;  // set on the thread under test only
std::atomic<long> g_mallocs{0}, g_frees{0}, g_news{0}, g_deletes{0};

// Counts the allocations of the calling thread while alive.
class CountAllocations {
 public:
  CountAllocations() { t_counting = true; }
  ~CountAllocations() { t_counting = false; }
};
long allocations() { return g_mallocs + g_frees + g_news + g_deletes; }
void resetCounts() { g_mallocs = g_frees = g_news = g_deletes = 0; }
}  // namespace

// glibc's allocator under its internal names: replacing malloc, calloc, realloc and free
// together is supported by glibc (its memalign family stays, and frees through free).
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void __libc_free(void*);

void* malloc(std::size_t n) {
  if (t_counting) g_mallocs.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t size) {
  if (t_counting) g_mallocs.fetch_add(1, std::memory_order_relaxed);
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t n) {
  if (t_counting) g_mallocs.fetch_add(1, std::memory_order_relaxed);
  return __libc_realloc(p, n);
}
void free(void* p) {
  if (t_counting && p) g_frees.fetch_add(1, std::memory_order_relaxed);
  __libc_free(p);
}
}

void* operator new(std::size_t n) {
  if (t_counting) g_news.fetch_add(1, std::memory_order_relaxed);
  if (void* p = __libc_malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  if (t_counting) g_news.fetch_add(1, std::memory_order_relaxed);
  return __libc_malloc(n ? n : 1);
}
void* operator new[](std::size_t n, const std::nothrow_t& tag) noexcept { return operator new(n, tag); }
void operator delete(void* p) noexcept {
  if (t_counting && p) g_deletes.fetch_add(1, std::memory_order_relaxed);
  __libc_free(p);
}
void operator delete[](void* p) noexcept { operator delete(p); }
void operator delete(void* p, std::size_t) noexcept { operator delete(p); }
void operator delete[](void* p, std::size_t) noexcept { operator delete(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { operator delete(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { operator delete(p); }

// --- the pool under test ----------------------------------------------------------------
using namespace adroit::pneumatics;

namespace {

constexpr double kAtm = constants::kAtmosphere;
const std::vector<std::string> kModel = {"A_ARJ0_flex", "A_FFJ2_flex", "A_FFJ2_ext", "A_MFJ2_flex", "A_MFJ2_ext"};
const std::vector<std::string> kPool = {"A_FFJ2_flex", "A_FFJ2_ext", "A_MFJ2_flex"};
constexpr double kTick = 0.005;

PoolOptions options(const std::string& controller) {
  PoolOptions o;
  o.controller = controller;
  o.ilqg.jump_threshold = 20e3;  // the "limit, then hold" guess runs on every reference jump
  o.reference_timeout = 0.2;
  return o;
}

std::vector<PoolCylinder> cylinders(const std::vector<std::string>& names) {
  const CylinderSpec s = cylinderSpec("M9");
  std::vector<PoolCylinder> out;
  for (const auto& n : names) out.push_back({n, s.bore_area, s.dead_volume, ParametricParams{}});
  return out;
}

CylinderPool makePool(const std::string& controller) {
  return CylinderPool(cylinders(kPool), kModel, options(controller));
}

// kPool's cylinders as a group of two pools (iLQG, PIDF): the same commands, in kPool order.
PoolGroup makeGroup() {
  std::vector<std::unique_ptr<CylinderPool>> pools;
  pools.push_back(std::make_unique<CylinderPool>(cylinders({kPool[0], kPool[1]}), kModel, options("ilqg")));
  pools.push_back(std::make_unique<CylinderPool>(cylinders({kPool[2]}), kModel, options("pidf")));
  return PoolGroup(std::move(pools));
}

bool accepted(const StateVerdict& v) { return v.ok(); }
bool accepted(const Verdict& v) { return v.ok(); }
template <typename V>
bool accepted(const std::vector<V>& verdicts) {
  for (const V& v : verdicts)
    if (!v.ok()) return false;
  return true;
}

// The plant (the pool's own model per cylinder) and the input side, run on a thread whose
// allocations are not counted: a state every tick, a moving 100-step reference every 10th
// tick, with a gap of 0.3 s (longer than reference_timeout) every 2 s so that cylinders
// exhaust and are driven again (controller reset and restart), and a reference jump
// every second.
template <typename Target>  // CylinderPool or PoolGroup
class Feeder {
 public:
  explicit Feeder(Target& pool) : pool_(pool), p_(kModel.size(), kAtm) {}

  void feed(int k, const std::vector<double>& commands) {
    const double t = k * kTick;
    const ParametricModel model{ParametricParams{}};
    ParametricInputs in;
    in.volume = cylinderSpec("M9").dead_volume;
    for (std::size_t i = 0; i < kPool.size(); ++i) p_[i + 1] = model.step(p_[i + 1], commands[i], kTick, in);
    ASSERT_TRUE(accepted(pool_.setState(t, t, kModel, p_, length_, rate_, 620e3)));
    const bool gap = std::fmod(t, 2.0) > 1.7;
    if (k % 10 == 0 && !gap) {
      const double level = std::fmod(t, 1.0) < 0.5 ? 4.0 : 10.0;  // N, jumps
      for (int s = 0; s < 100; ++s)
        for (std::size_t j = 0; j < kPool.size(); ++j) force_[s * kPool.size() + j] = level + std::sin(t + 0.01 * s + j);
      ASSERT_TRUE(accepted(pool_.setReference(t, t, 0.005, 100, kPool, force_)));
    }
  }

 private:
  Target& pool_;
  std::vector<double> p_, length_ = std::vector<double>(kModel.size(), 0.01),
                          rate_ = std::vector<double>(kModel.size(), 0.0),
                          force_ = std::vector<double>(100 * kPool.size());
};

}  // namespace

TEST(AllocationHook, CatchesAnAllocationOnTheCountedThreadOnly) {
  resetCounts();
  {
    const CountAllocations counting;
    std::vector<double> v(10, 1.0);
    EXPECT_EQ(v.size(), 10u);
  }
  EXPECT_GE(g_news.load(), 1);
  EXPECT_GE(g_deletes.load(), 1);
  // Another thread allocating while this one counts is not counted.
  std::atomic<int> step{0};
  std::thread other([&step] {
    while (step.load() != 1) std::this_thread::yield();
    std::vector<int> v(1000, 7);
    step.store(v.size() == 1000 ? 2 : 3);
  });
  resetCounts();
  {
    const CountAllocations counting;
    step.store(1);
    while (step.load() < 2) std::this_thread::yield();
  }
  other.join();
  EXPECT_EQ(step.load(), 2);
  EXPECT_EQ(allocations(), 0);
  resetCounts();
  {
    const CountAllocations counting;
    void* volatile p = std::malloc(32);  // malloc itself is caught, too (volatile: not elided)
    std::free(p);
  }
  EXPECT_EQ(g_mallocs.load(), 1);
  EXPECT_EQ(g_frees.load(), 1);
}

// Inputs fed between the ticks on the same thread, with counting off around them.
TEST(PoolRealtime, TickAllocatesNothingAfterWarmUp) {
  for (const char* controller : {"ilqg", "pidf"}) {
    CylinderPool pool = makePool(controller);
    CommandSlot slot(emptyCommand(pool.size()));
    Feeder<CylinderPool> feeder(pool);
    std::vector<double> commands(pool.size(), -5.0);
    long during = 0;
    int driven_ticks = 0, exhaust_ticks = 0;
    for (int k = 0; k < 3000; ++k) {
      feeder.feed(k, commands);
      if (k == 500) resetCounts();  // warm-up over: every buffer has been used
      {
        const CountAllocations counting;
        const std::vector<double>& u = pool.update(k * kTick);
        putCommand(slot, k * kTick, u);
      }
      if (k >= 500) during = allocations();
      // The consumer side (the publisher thread in the node), not counted.
      if (slot.take()) commands = slot.front().volts;
      (pool.exhausting() == 0 ? driven_ticks : exhaust_ticks) += 1;
      if (k % 200 == 0) pool.takeWindow();
    }
    EXPECT_EQ(during, 0) << controller << ": mallocs " << g_mallocs << " frees " << g_frees << " news " << g_news
                         << " deletes " << g_deletes;
    // The run did what it claims: cylinders were driven, timed out, and were driven again.
    EXPECT_GT(driven_ticks, 2000) << controller;
    EXPECT_GT(exhaust_ticks, 50) << controller;
    EXPECT_GE(pool.counters().reference_timeouts, 3u) << controller;
    EXPECT_GT(pool.takeWindow().tracking_samples, 0u) << controller;
  }
}

// The same with the inputs and the consumer on their own threads, as in the node: only the
// tick thread counts. The tick never waits for the others, so it simply runs its ticks.
TEST(PoolRealtime, TickAllocatesNothingWithConcurrentInputs) {
  CylinderPool pool = makePool("ilqg");
  CommandSlot slot(emptyCommand(pool.size()));
  std::atomic<int> tick{-1}, fed{-1};
  std::atomic<bool> done{false};
  std::thread input([&] {
    Feeder<CylinderPool> feeder(pool);
    std::vector<double> commands(pool.size(), -5.0);
    while (!done) {
      const int k = tick.load();
      if (k == fed.load()) {
        std::this_thread::yield();
        continue;
      }
      feeder.feed(k, commands);
      if (slot.take()) commands = slot.front().volts;
      if (k % 200 == 0) pool.takeWindow();
      fed.store(k);
    }
  });
  long during = 0;
  std::thread ticker([&] {
    for (int k = 0; k < 3000; ++k) {
      tick.store(k);
      while (fed.load() != k) std::this_thread::yield();  // this tick's state is in (not counted)
      const CountAllocations counting;
      if (k == 500) resetCounts();
      const std::vector<double>& u = pool.update(k * kTick);
      putCommand(slot, k * kTick, u);
      if (k >= 500) during = allocations();
    }
  });
  ticker.join();
  done = true;
  input.join();
  EXPECT_EQ(during, 0) << "mallocs " << g_mallocs << " frees " << g_frees << " news " << g_news << " deletes "
                       << g_deletes;
  EXPECT_EQ(pool.counters().ticks, 3000u);
}

// A group ticks its pools in turn and gathers their commands into one: nothing allocated
// either, with the inputs (names resolved once for the group) fed between the ticks.
TEST(PoolRealtime, GroupTickAllocatesNothingAfterWarmUp) {
  PoolGroup group = makeGroup();
  CommandSlot slot(emptyCommand(group.names().size()));
  Feeder<PoolGroup> feeder(group);
  std::vector<double> commands(group.names().size(), -5.0);
  long during = 0;
  int driven_ticks = 0;
  for (int k = 0; k < 3000; ++k) {
    feeder.feed(k, commands);
    if (k == 500) resetCounts();
    {
      const CountAllocations counting;
      putCommand(slot, k * kTick, group.update(k * kTick));
    }
    if (k >= 500) during = allocations();
    if (slot.take()) commands = slot.front().volts;
    driven_ticks += group.pool(0).exhausting() == 0 && group.pool(1).exhausting() == 0;
    if (k % 200 == 0) group.pool(k / 200 % 2).takeWindow();
  }
  EXPECT_EQ(during, 0) << "mallocs " << g_mallocs << " frees " << g_frees << " news " << g_news << " deletes "
                       << g_deletes;
  EXPECT_GT(driven_ticks, 2000);
  EXPECT_GE(group.pool(0).counters().reference_timeouts, 2u);
  EXPECT_GE(group.pool(1).counters().reference_timeouts, 1u);
}
