// Nothing allocates in the simulation loop after warm-up (DESIGN.md §2: "nothing allocates
// in a 200 Hz or 500 Hz loop after start-up"): SimulatedRobot::step() and accepted
// commands, in both actuation modes, with sensor realism on.
//
// This binary replaces the global operator new / delete (every standard overload) and
// MuJoCo's allocator hook with versions that count allocations made on a thread while that
// thread has opened a counting window. Everything else (gtest, model loading) allocates
// as usual and is not counted.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <new>
#include <string>
#include <vector>

#include "adroit_driver/simulated_robot.h"

namespace {

thread_local bool t_counting = false;
thread_local std::size_t t_allocations = 0;

void* allocate(std::size_t size, std::size_t alignment) {
  if (t_counting) ++t_allocations;
  void* p = nullptr;
  if (alignment <= alignof(std::max_align_t)) {
    p = std::malloc(size ? size : 1);
  } else if (posix_memalign(&p, alignment, size ? size : 1) != 0) {
    p = nullptr;
  }
  return p;
}

void* allocateOrThrow(std::size_t size, std::size_t alignment) {
  void* p = allocate(size, alignment);
  if (!p) throw std::bad_alloc();
  return p;
}

// MuJoCo's own heap (mju_malloc): 64-byte aligned like its default allocator needs.
void* mujocoMalloc(std::size_t size) { return allocate(size, 64); }
void mujocoFree(void* p) { std::free(p); }

// Installed before main(), so every MuJoCo buffer is allocated and freed by the same pair.
const bool kMujocoHooked = [] {
  mju_user_malloc = mujocoMalloc;
  mju_user_free = mujocoFree;
  return true;
}();

// Counts the allocations this thread makes while alive.
class AllocationWindow {
 public:
  AllocationWindow() {
    t_allocations = 0;
    t_counting = true;
  }
  ~AllocationWindow() { t_counting = false; }
  std::size_t count() const { return t_allocations; }
};

}  // namespace

void* operator new(std::size_t n) { return allocateOrThrow(n, 0); }
void* operator new[](std::size_t n) { return allocateOrThrow(n, 0); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return allocate(n, 0); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return allocate(n, 0); }
void* operator new(std::size_t n, std::align_val_t a) { return allocateOrThrow(n, static_cast<std::size_t>(a)); }
void* operator new[](std::size_t n, std::align_val_t a) { return allocateOrThrow(n, static_cast<std::size_t>(a)); }
void* operator new(std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  return allocate(n, static_cast<std::size_t>(a));
}
void* operator new[](std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  return allocate(n, static_cast<std::size_t>(a));
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }

namespace adroit::driver {
namespace {

// The counter sees what it must: every kind of allocation inside the window, none outside.
TEST(StepAllocations, TheCounterSeesAllocationsInsideTheWindowOnly) {
  ASSERT_TRUE(kMujocoHooked);
  auto* outside = new std::vector<double>(100);
  struct alignas(128) Wide {
    double x[16];
  };
  std::size_t counted;
  {
    AllocationWindow window;
    auto* plain = new int(1);
    auto* array = new double[8];
    auto* nothrow = new (std::nothrow) int(2);
    auto* aligned = new Wide;
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(aligned) % alignof(Wide), 0u);
    std::vector<double> grown;
    grown.push_back(1.0);
    const std::string text(100, 'x');  // beyond the small-string buffer
    void* mj = mju_malloc(64);
    mju_free(mj);
    delete plain;
    delete[] array;
    delete nothrow;
    delete aligned;
    counted = window.count();
  }
  EXPECT_EQ(counted, 7u);
  delete outside;
  AllocationWindow empty;
  EXPECT_EQ(empty.count(), 0u);
}

struct Case {
  const char* scene;
  ActuationMode mode;
};

// Builds the robot, commands every cylinder, warms up, then counts over 3000 steps with
// a 200 Hz controller's commands (every 5 ms, alternating values) in between.
std::size_t allocationsInSteadyRunning(const Case& c) {
  SimConfig config;
  config.model_path = std::string(ADROIT_MJCF_DIR) + "/" + c.scene + ".xml";
  config.mode = c.mode;
  config.sensors.enabled = true;
  SimulatedRobot robot(config);
  const std::size_t n = robot.cylinderNames().size();
  std::vector<std::uint16_t> index(n);
  for (std::size_t i = 0; i < n; ++i) index[i] = static_cast<std::uint16_t>(i);
  const bool pneumatic = c.mode == ActuationMode::kPneumatic;
  const std::vector<double> low(n, pneumatic ? 0.5 : 2.0), high(n, pneumatic ? 2.0 : 8.0);
  const std::vector<std::string> some_names = {robot.cylinderNames()[0], robot.cylinderNames()[n - 1]};
  const std::vector<double> some_values = {pneumatic ? 1.0 : 4.0, pneumatic ? 1.5 : 6.0};
  auto command = [&](int k) {
    // By index (all cylinders) and, every other time, by name (a pool's subset).
    const auto& values = (k / 5) % 2 ? high : low;
    const CommandResult all = pneumatic ? robot.commandValves({}, index, values) : robot.commandForces({}, index, values);
    EXPECT_TRUE(all.applied) << all.error;
    if ((k / 5) % 2) {
      const CommandResult some = pneumatic ? robot.commandValves(some_names, {}, some_values)
                                           : robot.commandForces(some_names, {}, some_values);
      EXPECT_TRUE(some.applied) << some.error;
    }
  };
  for (int k = 0; k < 100; ++k) {
    if (k % 5 == 0) command(k);
    robot.step();
  }
  std::size_t counted;
  {
    AllocationWindow window;
    for (int k = 0; k < 3000; ++k) {
      if (k % 5 == 0) command(k);  // 5 steps = 10 ms: within the 50 ms watchdog
      robot.step();
    }
    counted = window.count();
  }
  EXPECT_FALSE(robot.safety().safe_state) << "the run must be the normal one";
  EXPECT_TRUE(robot.sensedIsFinite());
  EXPECT_EQ(robot.counters().steps, 3100u);
  return counted;
}

TEST(StepAllocations, PneumaticWithSensorRealismAllocatesNothingAfterWarmUp) {
  for (const char* scene : {"arm_hand", "ball"})
    EXPECT_EQ(allocationsInSteadyRunning({scene, ActuationMode::kPneumatic}), 0u) << scene;
}

TEST(StepAllocations, ForceModeAllocatesNothingAfterWarmUp) {
  for (const char* scene : {"arm_hand", "ball"})
    EXPECT_EQ(allocationsInSteadyRunning({scene, ActuationMode::kForce}), 0u) << scene;
}

// The safe state (e-stop) and its release are not hot paths, but stepping in the safe
// state is: it must not allocate either.
TEST(StepAllocations, SteppingInTheSafeStateAllocatesNothing) {
  SimConfig config;
  config.model_path = std::string(ADROIT_MJCF_DIR) + "/ball.xml";
  SimulatedRobot robot(config);
  for (int k = 0; k < 100; ++k) robot.step();
  robot.estop();
  for (int k = 0; k < 10; ++k) robot.step();
  AllocationWindow window;
  for (int k = 0; k < 1000; ++k) robot.step();
  EXPECT_EQ(window.count(), 0u);
}

}  // namespace
}  // namespace adroit::driver
