// adroit_learning trainer node: trajectory-centric RL jobs started with rosservice.
//
//   /adroit_learning/train           adroit_msgs/Train: starts a job, answers at once with its id
//   /adroit_learning/status          adroit_msgs/TrainStatus
//   /adroit_learning/cancel          std_srvs/Trigger
//   /adroit_learning/execute_policy  adroit_msgs/ExecutePolicy: one rollout of a saved policy's mean
//   /adroit_learning/progress        adroit_msgs/TrainProgress, one per iteration
//
// Private parameters: ~backend (driver | sim_workers), ~drivers (namespaces of the drivers
// the driver backend uses, default [/adroit]), ~workers (sim_workers threads, 0 = cores),
// ~pacing (lockstep: the simulation driver steps when told | realtime: hardware, or a driver
// running in real time), ~tasks_dir, ~default_output_dir, ~timeout (s, a driver's answer),
// ~plot (write learning_curve.png after every iteration), ~transport_priority (realtime pacing:
// SCHED_FIFO priority of roscpp's threads, 0 = normal scheduling; see below).
//
// The job runs on its own thread; callbacks only read or set its shared state, so status and
// cancel answer while rollouts run.
#include <adroit_description/scenes.h>
#include <adroit_core/number_text.h>
#include <adroit_learning/network_policy.h>
#include <adroit_learning/policy_library.h>
#include <adroit_learning/policy_loader.h>
#include <adroit_learning/sim_rollouts.h>
#include <adroit_learning/trainer.h>
#include <adroit_learning/trainer_requests.h>
#include <adroit_msgs/ExecutePolicy.h>
#include <adroit_msgs/Train.h>
#include <adroit_msgs/TrainProgress.h>
#include <adroit_msgs/TrainStatus.h>
#include <adroit_ros/node_main.h>
#include <adroit_ros/params.h>
#include <adroit_ros/realtime.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>
#include <sys/stat.h>
#include <unistd.h>

#include <adroit_core/mujoco_model.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include "demonstration_bag.h"
#include "driver_rollouts.h"

namespace adroit::learning_node {

namespace {

bool makeDirectories(const std::string& path) {
  for (std::size_t pos = 1; pos <= path.size(); ++pos) {
    if (pos < path.size() && path[pos] != '/') continue;
    const std::string prefix = path.substr(0, pos);
    if (::mkdir(prefix.c_str(), 0755) != 0 && errno != EEXIST) return false;
  }
  return true;
}

// "" when `dir` exists (or can be made) and a file can be written in it, else why not.
std::string writableDirectory(const std::string& dir) {
  if (!makeDirectories(dir)) return "cannot create output directory '" + dir + "': " + std::strerror(errno);
  const std::string probe = dir + "/.write_test";
  FILE* f = std::fopen(probe.c_str(), "w");
  if (!f) return "output directory '" + dir + "' is not writable: " + std::strerror(errno);
  std::fclose(f);
  std::remove(probe.c_str());
  return "";
}

}  // namespace

class TrainerNode {
 public:
  TrainerNode(ros::NodeHandle& nh, ros::NodeHandle& pnh) : nh_(nh) {
    rosutil::Params params(pnh);
    params.checkKeys("", {"backend", "drivers", "workers", "tasks_dir", "default_output_dir", "timeout",
                          "plot", "pacing", "transport_priority"});
    backend_ = params.string("backend", "driver");
    if (backend_ != "driver" && backend_ != "sim_workers") params.fail("backend", "must be driver or sim_workers");
    drivers_ = params.strings("drivers");
    if (drivers_.empty()) drivers_ = {"/adroit"};
    workers_ = params.integer("workers", 0, 0, 64);
    const std::string pacing = params.string("pacing", "lockstep");
    if (pacing != "lockstep" && pacing != "realtime") params.fail("pacing", "must be lockstep or realtime");
    pacing_ = pacing == "realtime" ? learning_node::Pacing::kRealtime : learning_node::Pacing::kLockstep;
    // roscpp writes a published message to its socket on its poll thread, not on the thread
    // that publishes: the keep-alive's commands (SCHED_FIFO 10, driver_rollouts.cpp) leave the
    // process only when that thread runs. Under normal scheduling it can wait 50-100 ms behind
    // the stack's SCHED_FIFO threads (adroit_ros/realtime.h), longer than the driver's watchdog.
    const int transport_priority = params.integer("transport_priority", 11, 0, 99);
    if (pacing_ == learning_node::Pacing::kRealtime && transport_priority > 0) {
      std::string error;
      if (!rosutil::fifoRosThreads(transport_priority, &error))
        ROS_WARN("adroit_learning: roscpp's threads keep normal scheduling (%s): on a busy machine the keep-alive's "
                 "commands may reach the driver late and trip its watchdog",
                 error.c_str());
    }
    tasks_dir_ = params.string("tasks_dir", ros::package::getPath("adroit_learning") + "/config/tasks");
    if (trainingTaskNames(tasks_dir_).empty()) params.fail("tasks_dir", "no task files (*.yaml) in '" + tasks_dir_ + "'");
    const char* home = std::getenv("ROS_HOME");
    default_output_dir_ = params.string("default_output_dir", std::string(home ? home : "/tmp") + "/adroit_learning");
    timeout_ = params.number("timeout", 5.0, 0.1, 600.0);
    plot_ = params.boolean("plot", true);
    plot_script_ = ros::package::getPath("adroit_learning") + "/scripts/plot_learning_curve.py";

    ros::NodeHandle ln("adroit_learning");
    progress_pub_ = ln.advertise<adroit_msgs::TrainProgress>("progress", 20);
    services_.push_back(ln.advertiseService("train", &TrainerNode::onTrain, this));
    services_.push_back(ln.advertiseService("status", &TrainerNode::onStatus, this));
    services_.push_back(ln.advertiseService("cancel", &TrainerNode::onCancel, this));
    services_.push_back(ln.advertiseService("execute_policy", &TrainerNode::onExecute, this));
    ROS_INFO("adroit_learning: ready, backend %s, tasks in %s", backend_.c_str(), tasks_dir_.c_str());
  }

  ~TrainerNode() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (trainer_) trainer_->cancel();
    }
    if (job_.joinable()) job_.join();
  }

 private:
  // The backend for a task: the task scene's model for qpos layout and ranges.
  std::unique_ptr<RolloutBackend> makeBackend(const TrainingTask& task, const std::string& kind) {
    const std::string share = ros::package::getPath("adroit_description");
    const std::string model_path = description::sceneFile(share, task.scene, false);
    if (kind == "sim_workers") {
      driver::SimConfig config;
      config.model_path = model_path;
      config.mode = driver::ActuationMode::kPneumatic;
      return std::make_unique<SimRollouts>(config, workers_);
    }
    return std::make_unique<DriverRollouts>(nh_, drivers_, loadModelFile(model_path).model, timeout_, pacing_);
  }

  // Train, status, cancel and execute_policy all answer from these two (under mutex_), so they
  // never disagree on whether the robot is busy, and with what.
  bool busy() const { return state_ == "running" || executing_; }
  std::string busyMessage() const {
    if (state_ == "running") return "a job is running (" + job_id_ + "); cancel it first with /adroit_learning/cancel";
    return "execute_policy is running " + executing_path_ + "; cancel it with /adroit_learning/cancel";
  }

  // The request's counts, checked before any conversion to int (3e9 is not "not positive").
  static std::string countsProblem(const adroit_msgs::Train::Request& req) {
    std::string bad = countProblem("iterations", req.iterations, 1, kMaxTrainIterations);
    if (bad.empty() && req.rollouts != 0)
      bad = countProblem("rollouts (samples per iteration)", req.rollouts, 2, kMaxTrainRollouts);
    if (bad.empty()) bad = countProblem("initial_state_noise_from", req.initial_state_noise_from, 0, kMaxTrainIterations);
    return bad;
  }

  bool onTrain(adroit_msgs::Train::Request& req, adroit_msgs::Train::Response& res) {
    res.accepted = false;
    res.message = countsProblem(req);
    if (!res.message.empty()) return true;
    TrainingTask task;
    try {
      task = findTrainingTask(tasks_dir_, req.task);
    } catch (const std::exception& e) {
      res.message = e.what();
      return true;
    }
    // Before the lock: exporting ten bags takes seconds, and status must answer meanwhile.
    // Nothing of the node's state is touched here.
    std::vector<Demonstration> demonstrations;
    if (!req.demonstrations.empty()) {
      res.message = readDemonstrations(req.demonstrations, task, demonstrations);
      if (!res.message.empty()) return true;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    if (busy()) {
      res.message = busyMessage();
      return true;
    }
    TrainerSettings settings;
    settings.iterations = static_cast<int>(req.iterations);
    settings.samples = req.rollouts == 0 ? 5 : static_cast<int>(req.rollouts);
    settings.seed = req.seed != 0 ? req.seed : static_cast<std::uint64_t>(std::time(nullptr));
    settings.noise_scale = req.noise_level == 0 ? 1.0 : req.noise_level;
    settings.smoothing_width = req.smoothing_width;
    settings.initial_state_noise = req.initial_state_noise;
    settings.initial_state_noise_from = static_cast<int>(req.initial_state_noise_from);
    const std::string bad = validate(settings);
    if (!bad.empty()) {
      res.message = bad;
      return true;
    }
    char stamp[32];
    const std::time_t now = std::time(nullptr);
    std::strftime(stamp, sizeof(stamp), "%Y%m%d-%H%M%S", std::localtime(&now));
    const std::string id = task.name + "-" + stamp + "-" + std::to_string(settings.seed);
    settings.output_dir = req.output_dir.empty() ? default_output_dir_ + "/" + id : req.output_dir;
    const std::string unwritable = writableDirectory(settings.output_dir);
    if (!unwritable.empty()) {
      res.message = unwritable;
      return true;
    }
    if (job_.joinable()) job_.join();  // the previous job has ended (not busy)
    job_id_ = id;
    state_ = "running";
    message_ = "starting";
    iteration_ = 0;
    iterations_ = settings.iterations * static_cast<unsigned>(std::max<std::size_t>(1, demonstrations.size()));
    mean_cost_ = best_cost_ = std::numeric_limits<double>::quiet_NaN();
    success_rate_ = 0;
    const std::size_t policies = demonstrations.size();
    job_ = std::thread(&TrainerNode::runJob, this, task, settings, id, std::move(demonstrations));
    res.accepted = true;
    res.job_id = id;
    res.message = "training " + task.name + " for " + std::to_string(settings.iterations) + " iterations x " +
                  std::to_string(settings.samples) + " rollouts on backend " + backend_ + ", output in " +
                  settings.output_dir +
                  (policies == 0 ? "" : policies == 1 ? ", imitating " + req.demonstrations
                                                      : ", " + std::to_string(policies) + " local policies, one per demonstration in " +
                                                            req.demonstrations + " (library.txt)");
    return true;
  }

  // The demonstrations a request names, each fit for `task`: a bag, or a directory of bags (a
  // library job: one local policy per bag, thesis 11.4). "" when every one is, else the one line
  // that refuses the request; nothing is trained then.
  static std::string readDemonstrations(const std::string& path, const TrainingTask& task,
                                        std::vector<Demonstration>& demonstrations) {
    std::vector<std::string> bags;
    std::error_code error;
    if (std::filesystem::is_directory(path, error)) {
      for (const auto& entry : std::filesystem::directory_iterator(path, error))
        if (entry.path().extension() == ".bag") bags.push_back(entry.path().string());
      std::sort(bags.begin(), bags.end());
      if (bags.empty()) return path + ": a directory without demonstration bags (*.bag)";
    } else {
      bags.push_back(path);
    }
    for (const std::string& bag : bags) {
      demonstrations.emplace_back();
      const std::string problem = readDemonstration(bag, task, demonstrations.back());
      if (!problem.empty()) return problem;
    }
    return "";
  }

  // One bag as a Demonstration fit for `task` (what `demos export` and the task-level checks say).
  static std::string readDemonstration(const std::string& bag, const TrainingTask& task, Demonstration& demonstration) {
    char work[] = "/tmp/adroit_demonstration_XXXXXX";
    if (!::mkdtemp(work)) return "cannot make a temporary directory for the demonstration: " + std::string(std::strerror(errno));
    std::string problem;
    try {
      demonstration = exportDemonstration(bag, task.control_dt, work);
      problem = demonstrationTaskMismatch(demonstration, task);
    } catch (const DemonstrationError& e) {
      problem = e.what();
    }
    std::filesystem::remove_all(work);
    return problem;
  }

  // Imitation (thesis 10.4) once the robot's layout is known: q_hat_t, the condition (the tube's
  // initial yaw) and the first iteration's controls come from the demonstration.
  static void imitate(const Demonstration& demo, const RolloutBackend& backend, TrainingTask& task,
                      TrainerSettings& settings) {
    const StateLayout layout(task, backend.jointNames(), backend.cylinderNames(), backend.hasObject());
    const std::string problem = demonstrationRobotMismatch(demo, layout);
    if (!problem.empty()) throw DemonstrationError(problem);
    imitateDemonstration(demo, layout, backend.objectGeometry(), task);
    settings.initial_actions = demonstrationActions(demo, layout, task.horizon);
  }

  // Which local policy of a library job is training (0 of 1 for a single policy).
  struct JobPart {
    int index = 0, count = 1;
  };

  // A job: one policy, or with several demonstrations a library job (thesis 11.4-11.5): one
  // local policy per demonstration, each in <output_dir>/yaw_NNN, then <output_dir>/library.txt.
  void runJob(TrainingTask task, TrainerSettings settings, std::string id, std::vector<Demonstration> demonstrations) {
    std::string state = "failed", message;
    try {
      std::unique_ptr<RolloutBackend> backend = makeBackend(task, backend_);
      if (demonstrations.empty()) {
        state = trainPolicy(task, settings, *backend, id, {}) ? "finished" : "cancelled";
      } else {
        PolicyLibrary library{task.name, task.scene, {}};
        const int count = static_cast<int>(demonstrations.size());
        for (int k = 0; k < count && state != "cancelled"; ++k) {
          TrainingTask local = task;
          TrainerSettings local_settings = settings;
          imitate(demonstrations[k], *backend, local, local_settings);
          if (count > 1) local_settings.output_dir = settings.output_dir + "/" + yawDirectory(*local.initial_object_yaw);
          if (!trainPolicy(local, local_settings, *backend, id, {k, count})) state = "cancelled";
          library.entries.push_back(
              {local.initial_object_yaw.value_or(0.0), yawDirectory(local.initial_object_yaw.value_or(0.0)) + "/final.tvlg",
               nullptr, ""});  // written only for several policies, each in its yaw directory
        }
        if (state != "cancelled") {
          state = "finished";
          if (count > 1) writePolicyLibrary(settings.output_dir + "/library.txt", library);
        }
      }
      message = state == "cancelled" ? "cancelled at iteration " + std::to_string(iteration_)
                                     : "done; policies and learning_curve.csv in " + settings.output_dir +
                                           (demonstrations.size() > 1 ? " (library.txt: one local policy per demonstration)" : "");
    } catch (const std::exception& e) {
      ROS_ERROR("adroit_learning: job %s failed: %s", id.c_str(), e.what());
      message = e.what();
    }
    // Only now, with the backend gone (its subscriptions closed), may another job or an
    // execute_policy call take the robot.
    finish(state, message);
  }

  static std::string yawDirectory(double yaw_deg) {
    char name[32];
    std::snprintf(name, sizeof(name), "yaw_%05.1f", yaw_deg);
    return name;
  }

  // Trains one policy to its final.tvlg; false when cancelled.
  bool trainPolicy(const TrainingTask& task, const TrainerSettings& settings, RolloutBackend& backend,
                   const std::string& id, JobPart part) {
    auto trainer = std::make_shared<Trainer>(task, settings, backend);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      trainer_ = trainer;
      if (cancel_requested_) trainer->cancel();
    }
    ROS_INFO("adroit_learning: job %s: %s, policy %d/%d%s, %d iterations x %d rollouts, state %d, actions %d, backend %s",
             id.c_str(), task.name.c_str(), part.index + 1, part.count,
             task.initial_object_yaw ? (" (yaw " + shortNumber(*task.initial_object_yaw) + " deg)").c_str() : "",
             settings.iterations, settings.samples, trainer->layout().nx(), trainer->layout().nu(), backend.name().c_str());
    while (!trainer->finished() && !trainer->cancelled()) {
      const IterationReport r = trainer->iterate();
      publish(id, task, settings, r, part);
      if (plot_) plot(settings.output_dir);
    }
    if (trainer->cancelled()) return false;
    writePolicyFile(settings.output_dir + "/final.tvlg",
                    trainer->policyFile(trainer->controller(), trainer->iteration(), std::numeric_limits<double>::quiet_NaN()));
    return true;
  }

  void finish(const std::string& state, const std::string& message) {
    std::lock_guard<std::mutex> lock(mutex_);
    state_ = state;
    message_ = message;
    trainer_.reset();
    cancel_requested_ = false;
    ROS_INFO("adroit_learning: job %s %s: %s", job_id_.c_str(), state.c_str(), message.c_str());
  }

  void publish(const std::string& id, const TrainingTask& task, const TrainerSettings& settings,
               const IterationReport& r, JobPart part) {
    adroit_msgs::TrainProgress m;
    m.header.stamp = ros::Time::now();
    m.job_id = id;
    m.task = task.name;
    m.iteration = r.iteration;
    m.iterations = settings.iterations;
    m.ok = r.ok;
    m.message = r.message;
    m.cost_mean = r.cost_mean;
    m.cost_std = r.cost_std;
    m.joint_rms_mean = r.joint_rms_mean;
    m.successes = r.successes;
    m.samples = r.samples;
    m.kl = r.kl;
    m.eta = r.eta;
    m.epsilon = r.epsilon;
    m.rollout_s = r.rollout_s;
    m.gmm_s = r.gmm_s;
    m.dynamics_s = r.dynamics_s;
    m.cost_s = r.cost_s;
    m.update_s = r.update_s;
    m.policy_path = r.policy_path;
    m.policy = static_cast<std::uint32_t>(part.index);
    m.policies = static_cast<std::uint32_t>(part.count);
    m.initial_object_yaw = task.initial_object_yaw.value_or(std::numeric_limits<double>::quiet_NaN());
    progress_pub_.publish(m);
    if (r.ok)
      ROS_INFO("adroit_learning: %s iteration %d/%d: cost %.4g +- %.3g, joint rms %.3f rad, %d/%d ok, KL %.3g "
               "(eps %.3g, eta %.3g); rollouts %.2f s, GMM %.2f s, fit %.2f s, update %.2f s",
               task.name.c_str(), r.iteration + 1, settings.iterations, r.cost_mean, r.cost_std, r.joint_rms_mean,
               r.successes, r.samples, r.kl, r.epsilon, r.eta, r.rollout_s, r.gmm_s, r.dynamics_s, r.update_s);
    else
      ROS_WARN("adroit_learning: %s iteration %d/%d: %s", task.name.c_str(), r.iteration + 1, settings.iterations,
               r.message.c_str());
    std::lock_guard<std::mutex> lock(mutex_);
    iteration_ = part.index * settings.iterations + r.iteration + 1;  // over the whole job
    if (r.ok) {
      mean_cost_ = r.cost_mean;
      if (!(best_cost_ <= r.cost_mean)) best_cost_ = r.cost_mean;
      success_rate_ = r.samples > 0 ? static_cast<double>(r.successes) / r.samples : 0.0;
    }
    message_ = (part.count > 1 ? "policy " + std::to_string(part.index + 1) + "/" + std::to_string(part.count) + ": " : "") +
               (r.ok ? "iteration " + std::to_string(r.iteration + 1) + " done" : r.message);
  }

  void plot(const std::string& dir) {
    // Off the callback threads (this is the job's thread); a missing matplotlib only warns. An
    // argument vector: the output directory comes from a request and is never shell text.
    const ProgramResult r = plotLearningCurve(plot_script_, dir);
    if (!r.ok()) ROS_WARN_ONCE("adroit_learning: %s/learning_curve.png not written (%s)", dir.c_str(), r.describe().c_str());
  }

  bool onStatus(adroit_msgs::TrainStatus::Request&, adroit_msgs::TrainStatus::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    res.state = executing_ ? "executing" : state_;
    res.job_id = job_id_;
    res.iteration = iteration_;
    res.iterations = iterations_;
    res.mean_cost = mean_cost_;
    res.best_cost = best_cost_;
    res.success_rate = success_rate_;
    res.message = executing_ ? "execute_policy is running " + executing_path_ : message_;
    return true;
  }

  bool onCancel(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (executing_) {
      execute_cancel_ = true;
      res.success = true;
      res.message = "cancelling execute_policy of " + executing_path_ + " (it stops at its next control step)";
      return true;
    }
    if (state_ != "running") {
      res.success = false;
      res.message = "no job is running";
      return true;
    }
    cancel_requested_ = true;
    if (trainer_) trainer_->cancel();
    res.success = true;
    res.message = "cancelling " + job_id_ + " (the current rollout stops at its next control step)";
    return true;
  }

  // What execute_policy runs: everything a request can get wrong is found here, before the
  // robot is claimed or a driver is touched.
  struct Execution {
    std::unique_ptr<Policy> policy;  // any kind (loadPolicy): TVLG file, library, network
    PolicyOrigin origin;
    TrainingTask task;               // horizon: the steps to run (the requested duration)
  };

  // The object of a scene, read from its model file (a library reads the tube's yaw with it).
  static ObjectGeometry sceneObjectGeometry(const std::string& scene) {
    const std::string share = ros::package::getPath("adroit_description");
    return objectGeometry(loadModelFile(description::sceneFile(share, scene, false)).model.get());
  }

  // The kind a request's policy_type names ("" = any); ExecutePolicy.srv's names are aliases.
  static std::string requestedKind(const std::string& policy_type) {
    if (policy_type.empty() || policy_type == "tvlg") return policy_type;
    if (policy_type == "library" || policy_type == "nearest") return "library";
    if (policy_type == "network" || policy_type == "neural") return "network";
    throw std::runtime_error("policy_type '" + policy_type +
                             "' is not available; known: tvlg, library (nearest), network (neural)");
  }

  Execution prepareExecution(const adroit_msgs::ExecutePolicy::Request& req) const {
    const std::string kind = requestedKind(req.policy_type);
    const std::string bad_duration = executeDurationProblem(req.duration);
    if (!bad_duration.empty()) throw std::runtime_error(bad_duration);
    Execution e;
    e.policy = loadPolicy(req.policy_path, PolicyContext{sceneObjectGeometry}, &e.origin);  // regular files only, bounded
    if (!kind.empty() && e.policy->kind() != kind)
      throw std::runtime_error(req.policy_path + ": a " + e.policy->kind() + " policy, the request asks for " +
                               req.policy_type);
    e.task = findTrainingTask(tasks_dir_, e.origin.task);
    if (std::abs(e.task.control_dt - e.origin.control_dt) > 1e-12)
      throw std::runtime_error(req.policy_path + ": control_dt " + std::to_string(e.origin.control_dt) + " s, task '" +
                               e.task.name + "' now has " + std::to_string(e.task.control_dt) + " s");
    // A time-invariant policy runs for the task's horizon unless a duration says otherwise.
    const int full = e.policy->horizon() > 0 ? e.policy->horizon() : e.task.horizon;
    e.task.horizon = executeHorizon(full, e.task.control_dt, req.duration);
    return e;
  }

  // One rollout of the policy's mean on the driver; the message of a success.
  std::string execute(Execution& e, double& final_cost) {
    TrainingTask& task = e.task;
    std::unique_ptr<RolloutBackend> backend = makeBackend(task, "driver");  // always on the robot
    const StateLayout layout(task, backend->jointNames(), backend->cylinderNames(), backend->hasObject());
    const std::string mismatch =
        e.policy->mismatch(layout.joint_names, layout.cylinder_names, backend->touchNames(), layout);
    if (!mismatch.empty()) throw std::runtime_error(mismatch);
    const TrajectoryCost cost(task, layout, backend->initialState(task, layout), backend->objectGeometry());
    // One rollout: the factory hands over the policy loaded (and checked) above.
    const PolicyFactory once = [&e] { return std::move(e.policy); };
    const std::vector<RolloutResult> results =
        backend->runPolicy(task, layout, once, {RolloutRequest{}}, task.horizon, execute_cancel_);
    if (!results.front().ok) throw std::runtime_error("rollout failed: " + results.front().error);
    const TaskOutcome outcome = cost.outcome(results.front().sample);
    final_cost = outcome.cost;
    char text[200];
    std::snprintf(text, sizeof(text), "ran %d steps of %s: cost %.4g, joint rms %.3f rad%s", task.horizon,
                  task.name.c_str(), outcome.cost, outcome.joint_rms, outcome.success ? ", success" : "");
    return text;
  }

  bool onExecute(adroit_msgs::ExecutePolicy::Request& req, adroit_msgs::ExecutePolicy::Response& res) {
    res.success = false;
    res.final_cost = std::numeric_limits<double>::quiet_NaN();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (busy()) {
        res.message = busyMessage();
        return true;
      }
    }
    Execution e;
    try {
      e = prepareExecution(req);
    } catch (const std::exception& error) {  // refused: nothing claimed, no driver touched
      res.message = error.what();
      ROS_WARN("adroit_learning: execute_policy %s refused: %s", req.policy_path.c_str(), error.what());
      return true;
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (busy()) {
        res.message = busyMessage();
        return true;
      }
      executing_ = true;
      executing_path_ = req.policy_path;
      execute_cancel_ = false;
    }
    try {
      res.message = execute(e, res.final_cost);
      res.success = true;
      ROS_INFO("adroit_learning: execute_policy %s: %s", req.policy_path.c_str(), res.message.c_str());
    } catch (const std::exception& error) {
      res.message = error.what();
      ROS_WARN("adroit_learning: execute_policy %s failed: %s", req.policy_path.c_str(), error.what());
    }
    std::lock_guard<std::mutex> lock(mutex_);
    executing_ = false;
    return true;
  }

  ros::NodeHandle nh_;
  std::string backend_, tasks_dir_, default_output_dir_, plot_script_;
  std::vector<std::string> drivers_;
  int workers_ = 0;
  double timeout_ = 5.0;
  learning_node::Pacing pacing_ = learning_node::Pacing::kLockstep;
  bool plot_ = true;
  ros::Publisher progress_pub_;
  std::vector<ros::ServiceServer> services_;

  std::mutex mutex_;  // guards everything below
  std::thread job_;
  std::shared_ptr<Trainer> trainer_;
  std::string state_ = "idle", job_id_, message_;
  unsigned iteration_ = 0, iterations_ = 0;
  double mean_cost_ = std::numeric_limits<double>::quiet_NaN(), best_cost_ = std::numeric_limits<double>::quiet_NaN();
  double success_rate_ = 0;
  bool cancel_requested_ = false, executing_ = false;
  std::string executing_path_;
  std::atomic<bool> execute_cancel_{false};  // read by the execute rollout without mutex_
};

}  // namespace adroit::learning_node

int main(int argc, char** argv) {
  adroit::registerNetworkPolicyReader();  // execute_policy runs network policy files too
  return adroit::rosutil::runNode<adroit::learning_node::TrainerNode>(argc, argv, "adroit_learning", 4);
}
