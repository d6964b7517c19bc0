// Driver benchmark (a program, not a test; needs a ROS master, see run_bench.sh):
//  1. throughput in lockstep mode, pneumatic, arm-hand scene with an object (ball), through
//     the real ROS driver with a subscriber in another process, next to a bare mj_step loop
//     on the same scene in the same run -> driver overhead (required <= 10 %);
//  2. the ROS-free core alone (where the overhead goes);
//  3. real-time mode: 500 Hz joint_states publication jitter p50/p99 and the real-time factor.
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <thread>

#include <ros/package.h>
#include <ros/ros.h>

#include "adroit_core/timing_stats.h"
#include "adroit_description/scenes.h"
#include "adroit_driver/sim_driver.h"
#include <std_srvs/SetBool.h>

using adroit::Stopwatch;
using namespace adroit::driver;

namespace {

// The ROS-free core for `steps` steps; records the actuator controls (tensions) it applied
// so the bare loop can replay the very same motion and contacts.
double coreStepsPerSecond(const std::string& path, int steps, std::vector<double>* ctrl_log) {
  SimConfig c;
  c.model_path = path;
  SimulatedRobot robot(c);
  const int nu = robot.model()->nu;
  ctrl_log->resize(static_cast<std::size_t>(steps) * nu);
  Stopwatch watch;
  for (int k = 0; k < steps; ++k) {
    robot.step();
    std::copy(robot.data()->ctrl, robot.data()->ctrl + nu, ctrl_log->begin() + static_cast<long>(k) * nu);
  }
  return steps / watch.elapsed();
}

// Bare MuJoCo on the same scene from the same keyframe, replaying the core's controls.
double bareStepsPerSecond(const std::string& path, int steps, const std::vector<double>& ctrl_log) {
  adroit::ModelPtr model = adroit::loadModelFile(path).model;
  adroit::DataPtr data = adroit::makeData(model.get());
  mj_resetDataKeyframe(model.get(), data.get(), mj_name2id(model.get(), mjOBJ_KEY, "home"));
  const int nu = model->nu;
  Stopwatch watch;
  for (int k = 0; k < steps; ++k) {
    std::copy(ctrl_log.begin() + static_cast<long>(k) * nu, ctrl_log.begin() + static_cast<long>(k + 1) * nu,
              data->ctrl);
    mj_step(model.get(), data.get());
  }
  return steps / watch.elapsed();
}

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
  const bool pass = op == "<=" ? value <= target : value >= target;
  std::printf("RESULT adroit_driver/%s %.4g %s target %s %g %s\n", figure.c_str(), value, unit.c_str(), op.c_str(),
              target, pass ? "PASS" : "FAIL");
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

  // --- lockstep throughput: the same trajectory (steps 0..span from the home keyframe,
  // no commands, same sensor seed) through the bare loop, the ROS-free core and the ROS
  // driver, so contacts and motion are identical. Best of three rounds each: this VM's
  // speed drifts with its neighbours.
  const int span = std::max(500, static_cast<int>(lockstep_seconds * 1000));
  auto lockstepRun = [&](const std::string& ns) {
    setDriverParams(ns, scene, false);
    ros::param::set(ns + "/start_paused", true);
    SimDriver driver{ros::NodeHandle(), ros::NodeHandle(ns)};
    driver.start();
    std::this_thread::sleep_for(std::chrono::seconds(1));  // let a listener connect
    std_srvs::SetBool run;
    run.request.data = false;
    Stopwatch watch;
    if (!ros::service::call("/adroit/pause", run)) return 0.0;
    while (driver.steps() < static_cast<std::uint64_t>(span)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    const double rate = driver.steps() / watch.elapsed();
    driver.stop();
    return rate;
  };
  double bare_rate = 0, core_rate = 0, alone_rate = 0, driver_rate = 0;
  std::vector<double> ctrl_log;
  for (int round = 0; round < 3; ++round) {
    core_rate = std::max(core_rate, coreStepsPerSecond(path, span, &ctrl_log));
    bare_rate = std::max(bare_rate, bareStepsPerSecond(path, span, ctrl_log));
    alone_rate = std::max(alone_rate, lockstepRun("/bench_alone_" + std::to_string(round)));
  }
  if (write(go[1], "g", 1) != 1) return 2;  // the listener subscribes to everything now
  std::this_thread::sleep_for(std::chrono::seconds(1));
  for (int round = 0; round < 3; ++round)
    driver_rate = std::max(driver_rate, lockstepRun("/bench_listened_" + std::to_string(round)));
  const double overhead_alone = 100.0 * (bare_rate / alone_rate - 1.0);
  const double overhead = 100.0 * (bare_rate / driver_rate - 1.0);
  std::printf("\n%-44s %12s %14s\n", "lockstep throughput", "steps/s", "us/step");
  std::printf("%-44s %12.0f %14.1f\n", "bare mj_step loop", bare_rate, 1e6 / bare_rate);
  std::printf("%-44s %12.0f %14.1f\n", "SimulatedRobot core (plant + sensors)", core_rate, 1e6 / core_rate);
  std::printf("%-44s %12.0f %14.1f\n", "ROS driver, lockstep, no subscriber", alone_rate, 1e6 / alone_rate);
  std::printf("%-44s %12.0f %14.1f\n", "ROS driver, lockstep, with a subscriber", driver_rate, 1e6 / driver_rate);
  std::printf("driver overhead vs bare mj_step: %.1f %% alone, %.1f %% with a subscriber process "
              "(core alone: %.1f %%)\n\n", overhead_alone, overhead, 100.0 * (bare_rate / core_rate - 1.0));

  // --- real-time jitter ----------------------------------------------------------------
  setDriverParams("/bench_realtime", scene, true);
  std::vector<double> intervals;
  double rtf = 0;
  {
    SimDriver driver(ros::NodeHandle(), ros::NodeHandle("/bench_realtime"));
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
              " RTF %.4f\n\n", realtime_seconds, intervals.size(), p50, p99, worst, rtf);

  result("lockstep_overhead_vs_mj_step", overhead_alone, "%", "<=", 10.0);
  result("lockstep_overhead_with_subscriber", overhead, "%", "<=", 10.0);
  result("lockstep_steps_per_second", driver_rate, "steps/s", ">=", 500.0);
  result("realtime_jitter_p50", p50, "us", "<=", 200.0);
  result("realtime_jitter_p99", p99, "us", "<=", 1000.0);
  result("realtime_rtf_error", std::abs(rtf - 1.0), "ratio", "<=", 0.05);

  spinner.stop();
  kill(child, SIGTERM);
  waitpid(child, nullptr, 0);
  return 0;
}
