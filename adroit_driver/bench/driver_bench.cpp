// Driver benchmark (a program, not a test; needs a ROS master, see run_bench.sh).
// Method: paired, interleaved blocks. The lockstep variants advance the same trajectory
// (home keyframe, no commands, same sensor seed) in blocks of B steps (~0.1 s each): block k
// of the bare mj_step loop, of the ROS-free core and of the ROS driver (through its real
// /adroit/step service) run back to back, in an order that cycles through all six
// permutations; each variant keeps its state between blocks. The overhead is the median
// over blocks of t_driver_k / t_bare_k - 1, so machine-speed drift slower than a block
// (this VM drifts by +-25 % between runs) cancels in each ratio.
//  1. throughput in lockstep mode, pneumatic, arm-hand scene with an object (ball), through
//     the real ROS driver, without and with a subscriber in another process, paired with a
//     bare mj_step loop on the same scene -> driver overhead (required <= 10 %);
//  2. the ROS-free core alone, paired the same way (where the overhead goes);
//  3. real-time mode: 500 Hz joint_states publication jitter p50/p99 and the real-time factor,
//     next to a reference: the same schedule kept by a bare thread without ROS (what the
//     machine itself allows; printed only).
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <numeric>
#include <sstream>
#include <string>
#include <thread>

#include <ros/package.h>
#include <ros/ros.h>

#include "adroit_core/timing_stats.h"
#include "adroit_description/scenes.h"
#include "adroit_driver/simulated_robot.h"
#include "robot_driver.h"

using adroit::Stopwatch;
using namespace adroit::driver;

namespace {

constexpr double kBlockSeconds = 0.1;  // target wall time of one bare block

// Child process: a subscriber to everything the driver streams, like a real consumer.
// It starts listening only when the parent writes to `go` (after the no-subscriber run).
[[noreturn]] void listen(int argc, char** argv, int go) {
  prctl(PR_SET_PDEATHSIG, SIGTERM);
  char byte;
  if (read(go, &byte, 1) != 1) std::_Exit(0);
  ros::init(argc, argv, "driver_bench_listener", ros::init_options::AnonymousName);
  ros::NodeHandle nh;
  std::uint64_t count = 0;
  auto js = nh.subscribe<sensor_msgs::JointState>("/adroit/joint_states", 100, [&count](const auto&) { ++count; });
  auto as = nh.subscribe<adroit_msgs::ActuatorStates>("/adroit/actuator_states", 100, [&count](const auto&) { ++count; });
  auto ts = nh.subscribe<adroit_msgs::Touch>("/adroit/touch", 100, [&count](const auto&) { ++count; });
  auto os = nh.subscribe<nav_msgs::Odometry>("/adroit/object/odom", 100, [&count](const auto&) { ++count; });
  ros::spin();
  std::_Exit(0);
}

void setDriverParams(const std::string& ns, const std::string& scene, bool realtime) {
  ros::param::set(ns + "/scene", scene);
  ros::param::set(ns + "/mode", "pneumatic");
  ros::param::set(ns + "/realtime", realtime);
  ros::param::set(ns + "/marker_rate", 0.0);
}

void result(const std::string& figure, double value, const std::string& unit, const std::string& op, double target) {
  std::printf("%s\n", adroit::resultLine("adroit_driver", figure, value, unit, op, target).c_str());
}

// The controls (tensions) the core applies at each step of the trajectory, so that the
// bare loop replays the very same motion and contacts.
std::vector<double> recordControls(const std::string& path, long steps) {
  SimConfig c;
  c.model_path = path;
  SimulatedRobot robot(c);
  const int nu = robot.model()->nu;
  std::vector<double> log(static_cast<std::size_t>(steps) * nu);
  for (long k = 0; k < steps; ++k) {
    robot.step();
    std::copy(robot.data()->ctrl, robot.data()->ctrl + nu, log.begin() + k * nu);
  }
  return log;
}

// Wall time of one core step, to size the blocks.
double coreStepSeconds(const std::string& path) {
  SimConfig c;
  c.model_path = path;
  SimulatedRobot robot(c);
  for (int k = 0; k < 100; ++k) robot.step();
  Stopwatch watch;
  for (int k = 0; k < 300; ++k) robot.step();
  return watch.elapsed() / 300;
}

// Platform reference for the real-time jitter: the core stepped by a bare thread that
// sleeps until each 2 ms deadline (the driver's schedule, priority and sleep, no ROS);
// intervals between the wake-ups (s).
std::vector<double> referenceIntervals(const std::string& path, double seconds) {
  std::vector<double> intervals;
  std::thread([&] {
    sched_param sp{};
    sp.sched_priority = 20;
    pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);  // best effort, like the driver
    SimConfig c;
    c.model_path = path;
    SimulatedRobot robot(c);
    using Clock = std::chrono::steady_clock;
    const auto origin = Clock::now() + std::chrono::milliseconds(2);
    auto previous = origin;
    for (long k = 1; k <= std::lround(seconds / 0.002); ++k) {
      robot.step();
      std::this_thread::sleep_until(origin + std::chrono::microseconds(2000 * k));
      const auto now = Clock::now();
      if (k > 1) intervals.push_back(std::chrono::duration<double>(now - previous).count());
      previous = now;
    }
  }).join();
  return intervals;
}

struct Column {
  std::vector<double> seconds;      // wall time per measured block
  std::vector<double> cpu_seconds;  // CPU time of this process (all threads) per block
};

// CPU time (user + system) of another process so far, from /proc (clock-tick resolution).
double otherProcessCpuSeconds(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  std::getline(in, line);
  const auto paren = line.rfind(')');
  if (paren == std::string::npos) return 0;
  std::istringstream fields(line.substr(paren + 2));
  std::string field;
  unsigned long long utime = 0, stime = 0;
  for (int k = 3; k <= 15 && fields >> field; ++k) {
    if (k == 14) utime = std::stoull(field);
    if (k == 15) stime = std::stoull(field);
  }
  return static_cast<double>(utime + stime) / sysconf(_SC_CLK_TCK);
}

// Scheduler statistics of one thread of this process (/proc schedstat): time on a CPU,
// time runnable but waiting for one (preempted), and how many times it was put on a CPU.
struct ThreadSched {
  double run = 0, wait = 0, slices = 0;
};
ThreadSched threadSched(long tid) {
  std::ifstream in("/proc/self/task/" + std::to_string(tid) + "/schedstat");
  unsigned long long run = 0, wait = 0, slices = 0;
  in >> run >> wait >> slices;
  return {run * 1e-9, wait * 1e-9, static_cast<double>(slices)};
}

double processCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

struct Phase {
  std::string label;
  int blocks = 0, block_steps = 0;
  std::array<Column, 3> columns;  // bare, core, driver
  double max_qpos_difference = 0;  // core vs bare at block ends (same trajectory?)
  ThreadSched sim_thread;          // of the driver's simulation thread, summed over its blocks
  bool ok = false;
};

enum { kBare = 0, kCore = 1, kDriver = 2 };

// The subscriber count of one of the driver's topics: a second handle on the same
// publication (roscpp shares it within the process) sees the driver's subscriber links.
template <typename M>
bool hasSubscriber(const std::string& topic) {
  ros::NodeHandle nh;
  return nh.advertise<M>(topic, 1).getNumSubscribers() > 0;
}

Phase pairedPhase(const std::string& label, const std::string& ns, const std::string& scene, const std::string& path,
                  int block_steps, int blocks, const std::vector<double>& ctrl_log, bool wait_for_subscriber) {
  Phase phase;
  phase.label = label;
  phase.blocks = blocks;
  phase.block_steps = block_steps;
  constexpr int kWarmup = 1;

  // Bare MuJoCo on the same scene from the same keyframe, replaying the core's controls.
  adroit::ModelPtr model = adroit::loadModelFile(path).model;
  adroit::DataPtr data = adroit::makeData(model.get());
  SimConfig c;
  c.model_path = path;
  SimulatedRobot robot(c);
  model->opt.timestep = robot.timestep();
  mj_resetDataKeyframe(model.get(), data.get(), mj_name2id(model.get(), mjOBJ_KEY, "home"));
  const int nu = model->nu, nq = model->nq;
  long bare_step = 0;

  setDriverParams(ns, scene, false);
  ros::param::set(ns + "/start_paused", true);
  const auto owned = makeSimDriver(ros::NodeHandle(), ros::NodeHandle(ns));
  RobotDriver& driver = *owned;
  driver.start();
  ros::NodeHandle nh;
  ros::ServiceClient step = nh.serviceClient<adroit_msgs::Step>("/adroit/step", true);
  if (!step.waitForExistence(ros::Duration(10))) {
    std::fprintf(stderr, "driver_bench: /adroit/step not advertised\n");
    return phase;
  }
  if (wait_for_subscriber) {
    Stopwatch watch;
    while (!(hasSubscriber<sensor_msgs::JointState>("/adroit/joint_states") &&
             hasSubscriber<adroit_msgs::ActuatorStates>("/adroit/actuator_states") &&
             hasSubscriber<adroit_msgs::Touch>("/adroit/touch") &&
             hasSubscriber<nav_msgs::Odometry>("/adroit/object/odom"))) {
      if (watch.elapsed() > 20) {
        std::fprintf(stderr, "driver_bench: the listener did not connect\n");
        return phase;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }

  auto runBare = [&] {
    for (int k = 0; k < block_steps; ++k, ++bare_step) {
      std::copy(ctrl_log.begin() + bare_step * nu, ctrl_log.begin() + (bare_step + 1) * nu, data->ctrl);
      mj_step(model.get(), data.get());
    }
    return true;
  };
  auto runCore = [&] {
    for (int k = 0; k < block_steps; ++k) robot.step();
    return true;
  };
  adroit_msgs::Step srv;
  srv.request.steps = static_cast<std::uint32_t>(block_steps);
  auto runDriver = [&] { return step.call(srv) && srv.response.success; };

  static constexpr int kOrders[6][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 2, 1}, {2, 1, 0}, {1, 0, 2}};
  for (int b = 0; b < kWarmup + blocks; ++b) {
    for (int v : kOrders[b % 6]) {
      const double cpu0 = processCpuSeconds();
      const ThreadSched sched0 = threadSched(driver.simulationThreadId());
      Stopwatch watch;
      const bool ok = v == kBare ? runBare() : v == kCore ? runCore() : runDriver();
      const double t = watch.elapsed();
      const double cpu = processCpuSeconds() - cpu0;
      if (!ok) {
        std::fprintf(stderr, "driver_bench: /adroit/step failed: %s\n", srv.response.message.c_str());
        driver.stop();
        return phase;
      }
      if (b >= kWarmup) {
        phase.columns[v].seconds.push_back(t);
        phase.columns[v].cpu_seconds.push_back(cpu);
        if (v == kDriver) {
          const ThreadSched sched1 = threadSched(driver.simulationThreadId());
          phase.sim_thread.run += sched1.run - sched0.run;
          phase.sim_thread.wait += sched1.wait - sched0.wait;
          phase.sim_thread.slices += sched1.slices - sched0.slices;
        }
      }
    }
    for (int i = 0; i < nq; ++i)
      phase.max_qpos_difference = std::max(phase.max_qpos_difference, std::abs(robot.data()->qpos[i] - data->qpos[i]));
  }
  const std::uint64_t expected = static_cast<std::uint64_t>(kWarmup + blocks) * block_steps;
  phase.ok = driver.steps() == expected && robot.counters().steps == expected;
  if (!phase.ok)
    std::fprintf(stderr, "driver_bench: step counts differ: driver %lu, core %lu, expected %lu\n",
                 static_cast<unsigned long>(driver.steps()), static_cast<unsigned long>(robot.counters().steps),
                 static_cast<unsigned long>(expected));
  driver.stop();
  return phase;
}

struct Ratios {
  double median = 0, mean = 0, p25 = 0, p75 = 0;  // of t / t_bare - 1, in %
};

Ratios ratios(const Column& variant, const Column& bare) {
  std::vector<double> r;
  for (std::size_t k = 0; k < variant.seconds.size(); ++k) r.push_back(100.0 * (variant.seconds[k] / bare.seconds[k] - 1));
  Ratios out;
  if (r.empty()) return out;
  out.median = adroit::percentile(r, 50);
  out.mean = std::accumulate(r.begin(), r.end(), 0.0) / r.size();
  out.p25 = adroit::percentile(r, 25);
  out.p75 = adroit::percentile(r, 75);
  return out;
}

double cpuMicrosPerStep(const Phase& p, int v) {
  const auto& s = p.columns[v].cpu_seconds;
  return 1e6 * std::accumulate(s.begin(), s.end(), 0.0) / (p.blocks * static_cast<double>(p.block_steps));
}

double stepsPerSecond(const Phase& p, int v) {
  const auto& s = p.columns[v].seconds;
  const double total = std::accumulate(s.begin(), s.end(), 0.0);
  return total > 0 ? p.blocks * static_cast<double>(p.block_steps) / total : 0.0;
}

void printPhase(const Phase& p) {
  static const char* kNames[3] = {"bare mj_step loop", "SimulatedRobot core (plant + sensors)", "ROS driver via /adroit/step"};
  std::printf("%s (%d blocks x %d steps per variant; core vs bare max |qpos diff| %.3g)\n", p.label.c_str(), p.blocks,
              p.block_steps, p.max_qpos_difference);
  for (int v = 0; v < 3; ++v) {
    const double rate = stepsPerSecond(p, v);
    std::printf("  %-38s %9.0f %9.1f %9.1f", kNames[v], rate, rate > 0 ? 1e6 / rate : 0.0, cpuMicrosPerStep(p, v));
    if (v == kBare) {
      std::printf("%10s %9s %19s\n", "-", "-", "-");
    } else {
      const Ratios r = ratios(p.columns[v], p.columns[kBare]);
      std::printf("%+9.1f %% %+8.1f %%   %+7.1f .. %+5.1f %%\n", r.median, r.mean, r.p25, r.p75);
    }
  }
  const double steps = p.blocks * static_cast<double>(p.block_steps);
  std::printf("  driver's simulation thread: on a CPU %.1f us/step, preempted (runnable, waiting) %.2f us/step, "
              "scheduled in %.0f times per block\n",
              1e6 * p.sim_thread.run / steps, 1e6 * p.sim_thread.wait / steps, p.sim_thread.slices / p.blocks);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string scene = argc > 1 ? argv[1] : "ball";
  const double lockstep_seconds = argc > 2 ? std::atof(argv[2]) : 5.0;
  const double realtime_seconds = argc > 3 ? std::atof(argv[3]) : 10.0;

  // The listener must not share this process: intra-process delivery skips serialisation.
  int go[2];
  if (pipe(go) != 0) return 2;
  const pid_t child = fork();
  if (child == 0) listen(argc, argv, go[0]);

  ros::init(argc, argv, "driver_bench", ros::init_options::NoSigintHandler);
  if (!ros::master::check()) {
    std::fprintf(stderr, "driver_bench: no ROS master (run bench/run_bench.sh)\n");
    kill(child, SIGTERM);
    return 2;
  }
  ros::param::set("/use_sim_time", true);
  ros::AsyncSpinner spinner(1);
  spinner.start();
  const std::string path =
      adroit::description::sceneFile(ros::package::getPath("adroit_description"), scene);
  std::printf("driver_bench: scene %s (%s), pneumatic mode, sensor realism on\n", scene.c_str(), path.c_str());

  // --- lockstep throughput, paired blocks (see the top of this file) ----------------------
  // Blocks of ~0.1 s of bare stepping; lockstep_seconds of bare stepping per phase.
  const double step_seconds = coreStepSeconds(path);
  const int block_steps = std::clamp(static_cast<int>(std::lround(kBlockSeconds / step_seconds / 50) * 50), 500, 1000);
  const int blocks = std::max(10, static_cast<int>(std::lround(lockstep_seconds / (block_steps * step_seconds))));
  const std::vector<double> ctrl_log = recordControls(path, static_cast<long>(blocks + 1) * block_steps);
  const Phase alone = pairedPhase("no subscriber", "/bench_alone", scene, path, block_steps, blocks, ctrl_log, false);
  if (write(go[1], "g", 1) != 1) return 2;  // the listener subscribes to everything now
  const double listener_cpu0 = otherProcessCpuSeconds(child);
  const Phase listened =
      pairedPhase("with a subscriber process", "/bench_listened", scene, path, block_steps, blocks, ctrl_log, true);
  const double listener_cpu = otherProcessCpuSeconds(child) - listener_cpu0;
  std::printf("\nlockstep throughput, paired interleaved blocks (order cycles through all 6 permutations)\n");
  std::printf("  %-38s %9s %9s %9s %10s %10s %19s\n", "", "steps/s", "us/step", "CPU us/", "median", "mean",
              "IQR (p25 .. p75)");
  std::printf("  %-38s %9s %9s %9s %41s\n", "", "(total)", "(wall)", "step (1)", "per block: t / t_bare - 1 (wall)");
  printPhase(alone);
  printPhase(listened);
  std::printf("(1) CPU time of the benchmark process, all threads (the driver's publisher and roscpp's threads "
              "included; the listener process excluded: it used %.1f us per driver step)\n",
              1e6 * listener_cpu / ((listened.blocks + 1.0) * listened.block_steps));
  const Ratios overhead_alone = ratios(alone.columns[kDriver], alone.columns[kBare]);
  const Ratios overhead = ratios(listened.columns[kDriver], listened.columns[kBare]);
  std::printf("driver overhead vs bare mj_step (median of paired blocks): %.1f %% alone, %.1f %% with a subscriber "
              "process\n\n", overhead_alone.median, overhead.median);

  // --- real-time jitter ----------------------------------------------------------------
  setDriverParams("/bench_realtime", scene, true);
  std::vector<double> intervals;
  double rtf = 0;
  {
    const auto owned = makeSimDriver(ros::NodeHandle(), ros::NodeHandle("/bench_realtime"));
    RobotDriver& driver = *owned;
    driver.collectJointIntervals(true);
    driver.start();
    std::this_thread::sleep_for(std::chrono::seconds(1));
    driver.takeJointIntervals();
    const std::uint64_t s0 = driver.steps();
    Stopwatch watch;
    std::this_thread::sleep_for(std::chrono::duration<double>(realtime_seconds));
    intervals = driver.takeJointIntervals();
    rtf = (driver.steps() - s0) * 0.002 / watch.elapsed();
    driver.stop();
  }
  std::vector<double> jitter;
  for (double i : intervals) jitter.push_back(std::abs(i - 0.002));
  const double p50 = adroit::percentile(jitter, 50) * 1e6, p99 = adroit::percentile(jitter, 99) * 1e6;
  const double worst = jitter.empty() ? 0 : *std::max_element(jitter.begin(), jitter.end()) * 1e6;
  std::printf("real time, %.0f s: %zu joint_states intervals, |interval - 2 ms| p50 %.1f us, p99 %.1f us, max %.1f us;"
              " RTF %.4f\n", realtime_seconds, intervals.size(), p50, p99, worst, rtf);
  // What the machine itself allows: the same schedule without ROS, just after.
  const double reference_seconds = std::min(realtime_seconds, 5.0);
  std::vector<double> reference = referenceIntervals(path, reference_seconds);
  for (double& i : reference) i = std::abs(i - 0.002) * 1e6;
  std::printf("  reference, %.0f s: the core stepped and slept until each 2 ms deadline by a bare thread (SCHED_FIFO "
              "20 if permitted): p50 %.1f us, p99 %.1f us, max %.1f us\n\n", reference_seconds,
              adroit::percentile(reference, 50), adroit::percentile(reference, 99),
              reference.empty() ? 0.0 : *std::max_element(reference.begin(), reference.end()));

  const bool ok = alone.ok && listened.ok;
  result("lockstep_overhead_vs_mj_step", ok ? overhead_alone.median : NAN, "%", "<=", 10.0);
  result("lockstep_overhead_with_subscriber", ok ? overhead.median : NAN, "%", "<=", 10.0);
  result("lockstep_steps_per_second", ok ? stepsPerSecond(listened, kDriver) : 0.0, "steps/s", ">=", 500.0);
  result("realtime_jitter_p50", p50, "us", "<=", 200.0);
  result("realtime_jitter_p99", p99, "us", "<=", 1000.0);
  result("realtime_rtf_error", std::abs(rtf - 1.0), "ratio", "<=", 0.05);

  spinner.stop();
  kill(child, SIGTERM);
  waitpid(child, nullptr, 0);
  return 0;
}
