// The simulation thread allocates nothing after start-up, in real time and in lockstep:
// the driver runs in this process against a real master, with everything that could make
// it allocate switched on (pneumatic plant, sensor realism, an object, valve commands
// arriving, markers and diagnostics listened to), and a global operator new counts the
// allocations made on the simulation thread alone.
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <new>
#include <thread>

#include <adroit_msgs/Reset.h>
#include <adroit_msgs/ValveCommand.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <visualization_msgs/MarkerArray.h>

#include "adroit_driver/simulated_robot.h"
#include "robot_driver.h"

namespace {
std::atomic<long> g_counted_thread{0};      // kernel tid whose allocations count (0 = none)
std::atomic<std::uint64_t> g_allocations{0};

void* allocate(std::size_t size) {
  // gettid is a system call, not an allocation: safe inside operator new.
  const long counted = g_counted_thread.load(std::memory_order_relaxed);
  if (counted != 0 && syscall(SYS_gettid) == counted) g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}
}  // namespace

void* operator new(std::size_t size) { return allocate(size); }
void* operator new[](std::size_t size) { return allocate(size); }
void* operator new(std::size_t size, const std::nothrow_t&) noexcept {
  try {
    return allocate(size);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t size, const std::nothrow_t& tag) noexcept { return operator new(size, tag); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace {

using Clock = std::chrono::steady_clock;

// Allocations on the simulation thread while `steps` more steps are simulated and at least
// `min_wall` seconds pass (so that diagnostics swap the timing buffers and markers are
// snapshot inside the window), with valve commands sent all along from this thread.
std::uint64_t allocationsOver(adroit::driver::RobotDriver& driver, std::uint64_t steps, ros::Publisher& valves,
                              double min_wall = 0) {
  adroit_msgs::ValveCommand cmd;
  cmd.index = {0, 1, 2, 3};
  cmd.volts = {0.5, -0.5, 0.2, -0.2};
  g_allocations = 0;
  g_counted_thread = driver.simulationThreadId();
  const std::uint64_t end = driver.steps() + steps;
  const auto start = Clock::now();
  const auto deadline = start + std::chrono::seconds(60);
  const auto min_end = start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(min_wall));
  while ((driver.steps() < end || Clock::now() < min_end) && Clock::now() < deadline) {
    valves.publish(cmd);  // keeps the watchdog fed: the robot is not in the safe state
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  g_counted_thread = 0;
  EXPECT_GE(driver.steps(), end) << "the simulation did not advance";
  return g_allocations.load();
}

TEST(SimulationThread, AllocatesNothingWhileStepping) {
  ros::NodeHandle nh, pnh("~");
  const bool lockstep = !pnh.param("realtime", true);
  const auto owned = adroit::driver::makeSimDriver(nh, ros::NodeHandle("~driver"));
  adroit::driver::RobotDriver& driver = *owned;
  ros::Publisher valves = nh.advertise<adroit_msgs::ValveCommand>("/adroit/valve_command", 100);
  int markers = 0, diagnostics = 0;
  auto marker_sub = nh.subscribe<visualization_msgs::MarkerArray>("/adroit/markers", 5,
                                                                  [&](const auto&) { ++markers; });
  auto diag_sub = nh.subscribe<diagnostic_msgs::DiagnosticArray>("/adroit/diagnostics", 5,
                                                                  [&](const auto&) { ++diagnostics; });
  ros::AsyncSpinner spinner(2);
  spinner.start();
  driver.start();
  ASSERT_TRUE(nh.ok());
  const long tid = [&] {
    for (int i = 0; i < 500 && driver.simulationThreadId() == 0; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    return driver.simulationThreadId();
  }();
  ASSERT_NE(tid, 0);

  // Warm-up: ring slots, timing buffers, the marker snapshot, first publications.
  allocationsOver(driver, 500, valves);  // warm-up: first publications, marker snapshot, timing buffers
  const int markers_before = markers, diagnostics_before = diagnostics;
  const std::uint64_t steady = allocationsOver(driver, lockstep ? 6000 : 3000, valves, 2.0);
  EXPECT_EQ(steady, 0u) << "allocations on the simulation thread while stepping ("
                        << (lockstep ? "lockstep" : "real time") << ")";
  EXPECT_GT(markers, markers_before) << "no markers in the window: the snapshot path was not exercised";
  EXPECT_GT(diagnostics, diagnostics_before + 2) << "too few diagnostics in the window: the timing swap was not exercised";

  // The hook does see the simulation thread: a reset runs there and allocates.
  ros::ServiceClient reset = nh.serviceClient<adroit_msgs::Reset>("/adroit/reset");
  adroit_msgs::Reset srv;
  srv.request.keyframe = "home";
  g_allocations = 0;
  g_counted_thread = tid;
  ASSERT_TRUE(reset.call(srv));
  g_counted_thread = 0;
  EXPECT_TRUE(srv.response.success) << srv.response.message;
  EXPECT_GT(g_allocations.load(), 0u) << "a reset on the simulation thread was not counted: the hook is blind";
  driver.stop();
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_sim_allocations");
  return RUN_ALL_TESTS();
}
