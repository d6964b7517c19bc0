// Evaluation of pickup policies over the tube's initial orientation (thesis ch. 11: figs.
// 11.2-11.10 and 11.13 per policy over the rod angle, 11.5/11.7-11.10 at random initial yaws,
// 11.12's cross-validation table), in simulation on the in-process workers (SimRollouts: the
// driver's own plant, sensors and safety). ROS-free.
//
//   pickup_eval --task pickup --policy NAME=PATH [--policy NAME=PATH ...]
//               [--replay-demos DIR_OR_FILES] [--sweep-step 2] [--random 100] [--seed 1]
//               [--workers 0] [--out DIR] [--cross-validate LIBRARY_FILE] [--trials 5]
//               [--trial-noise 0.02] [--require NAME=MIN_PERCENT ...] [--strict]
//               [--tasks-dir DIR] [--scene-file MJCF] [--plot-script PATH] [--no-plot]
//
// Policies: any file loadPolicy reads (TVLG, nearest-neighbour library, network), and with
// --replay-demos one open-loop replay per `demos export` file (demonstration_policy.h), named
// demo_<yaw>. Every rollout runs a fresh copy of its policy for the task's T steps; the tube
// starts at the yaw of the trial (RolloutRequest::object_yaw_deg), and success is the task's
// criterion (pickupSuccess, 11.4) at T.
//  (b) sweep: every policy at yaw 0, step, 2 step, ... < 180 degrees;
//  (c) random: N yaws uniform in [0, 180) drawn from --seed, the same for every policy; the
//      success rate with its 95 % Wilson interval;
//  (a) --cross-validate LIBRARY: every policy at each of the library's yaws (conditions A, B,
//      ...), --trials K rollouts each with the initial joints offset uniformly within
//      +-trial-noise/2 of each joint's range (the same offsets everywhere), and the random set.
// Every policy's action() is timed per control tick (a decorator Policy): p50/p99 in ms; TVLG
// policies give the baseline of the same run next to the networks.
//
// Writes to --out (default ./pickup_eval): sweep.csv, random.csv, summary.csv, summary.md,
// cross_validation.csv/.md (with --cross-validate), and through plot_pickup_eval.py sweep.png
// and random.png. Prints a table, then RESULT lines (DESIGN.md section 5):
//   RESULT adroit_learning/pickup_random_success/<name> <percent> % target >= <min> PASS|FAIL
//     for the policies named in --require; the others' rates are INFO lines (no target);
//   RESULT adroit_learning/pickup_inference_p99/<name> <ms> ms target <= 1 PASS|FAIL
//     for network policies;
//   RESULT adroit_learning/pickup_local_policy_ceiling <percent> % target >= <highest MIN> PASS|FAIL
//     with --require: the random yaws at which any TVLG policy (local or demonstration replay)
//     succeeds, the bound on what nearest neighbour over them can reach.
// Exit status: 0 (also when a target fails; 1 then with --strict); 2 for bad input (an option,
// a policy file loadPolicy refuses, a policy of another task or robot, a demonstration that
// cannot be replayed), which is one line on stderr before anything runs.
#include <adroit_core/bounded_file.h>
#include <adroit_core/command_line.h>
#include <adroit_core/normal_noise.h>
#include <adroit_core/number_text.h>
#include <adroit_core/run_program.h>
#include <adroit_core/timing_stats.h>
#include <adroit_description/scenes.h>
#include <adroit_learning/demonstration.h>
#include <adroit_learning/demonstration_policy.h>
#include <adroit_learning/network_policy.h>
#include <adroit_learning/policy_library.h>
#include <adroit_learning/policy_loader.h>
#include <adroit_learning/sim_rollouts.h>
#include <adroit_learning/trainer.h>
#include <adroit_learning/tvlg_policy.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace {

constexpr char kUsage[] =
    "usage: pickup_eval --task pickup --policy NAME=PATH [--policy NAME=PATH ...] [--replay-demos DIR_OR_FILES] "
    "[--sweep-step 2] [--random 100] [--seed 1] [--workers 0] [--out DIR] [--cross-validate LIBRARY_FILE] "
    "[--trials 5] [--trial-noise 0.02] [--require NAME=MIN_PERCENT ...] [--strict] [--tasks-dir DIR] "
    "[--scene-file MJCF] [--plot-script PATH] [--no-plot]";
constexpr double kInferenceTargetMs = 1.0;  // network_inference_bench's target per control tick
const double kNaN = std::numeric_limits<double>::quiet_NaN();

// Bad input: one line on stderr, exit status 2, nothing run.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// ---------------------------------------------------------------------------------------------
// Pure helpers (test_pickup_eval).

struct Interval {
  double low = 0, high = 0;
};

// 95 % (z = 1.96) Wilson score interval of a success rate; [0, 1] without trials.
Interval wilsonInterval(int successes, int trials, double z = 1.96) {
  if (trials <= 0) return {0.0, 1.0};
  const double n = trials, p = static_cast<double>(successes) / n, z2 = z * z;
  const double centre = (p + z2 / (2 * n)) / (1 + z2 / n);
  const double half = z / (1 + z2 / n) * std::sqrt(p * (1 - p) / n + z2 / (4 * n * n));
  return {std::max(0.0, centre - half), std::min(1.0, centre + half)};
}

// 0, step, 2 step, ... below 180 degrees (computed as i * step, no accumulated rounding).
std::vector<double> yawGrid(double step) {
  std::vector<double> yaws;
  for (int i = 0; i * step < 180.0 - 1e-9; ++i) yaws.push_back(i * step);
  return yaws;
}

// `count` yaws uniform in [0, 180) from `seed` (adroit::NormalNoise's uniform: the same on every
// machine and standard library).
std::vector<double> randomYaws(int count, std::uint64_t seed) {
  adroit::NormalNoise rng(seed);
  std::vector<double> yaws(static_cast<std::size_t>(std::max(0, count)));
  for (double& yaw : yaws) yaw = std::min(rng.uniform() * 180.0, std::nextafter(180.0, 0.0));
  return yaws;
}

// One CSV field (RFC 4180): quoted when it holds a comma, quote or line break.
std::string csvField(const std::string& text) {
  if (text.find_first_of(",\"\n\r") == std::string::npos) return text;
  std::string out = "\"";
  for (char c : text) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

// A number for CSV and tables: %.6g, empty for NaN.
std::string numberField(double value) { return std::isnan(value) ? std::string() : adroit::shortNumber(value); }

// Policy names go into file names, CSV and RESULT lines: letters, digits, '_', '-', '.', '+'.
bool validName(const std::string& name) {
  if (name.empty() || name.size() > 64) return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.' || c == '+';
  });
}

// "NAME=VALUE" -> (NAME, VALUE); InputError naming the option otherwise.
std::pair<std::string, std::string> splitAssignment(const std::string& option, const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == text.size())
    throw InputError(option + " needs NAME=VALUE, got '" + text + "'");
  const std::string name = text.substr(0, eq);
  if (!validName(name))
    throw InputError(option + ": name '" + name + "' must be 1-64 letters, digits, '_', '-', '.' or '+'");
  return {name, text.substr(eq + 1)};
}

// "--require NAME=MIN": MIN a percentage in [0, 100] ("80" or "80%").
std::pair<std::string, double> parseRequirement(const std::string& text) {
  auto [name, value] = splitAssignment("--require", text);
  if (!value.empty() && value.back() == '%') value.pop_back();
  char* end = nullptr;
  const double min = std::strtod(value.c_str(), &end);
  if (value.empty() || *end != '\0' || !(min >= 0 && min <= 100))
    throw InputError("--require " + name + ": the minimum success must be a percentage in [0, 100], got '" + value + "'");
  return {name, min};
}

// "demo_<yaw>" with the yaw to 0.1 degree (demo_30, demo_12.5).
std::string demoLabel(double yaw_deg) { return "demo_" + adroit::shortNumber(std::round(yaw_deg * 10) / 10); }

// `name`, or name_2, name_3, ... when taken.
std::string uniqueName(const std::string& name, const std::vector<std::string>& taken) {
  const auto used = [&](const std::string& n) { return std::find(taken.begin(), taken.end(), n) != taken.end(); };
  if (!used(name)) return name;
  for (int i = 2;; ++i)
    if (!used(name + "_" + std::to_string(i))) return name + "_" + std::to_string(i);
}

// Condition labels of fig. 11.12: A, B, ..., Z, AA, AB, ...
std::string conditionLabel(std::size_t index) {
  std::string label;
  for (std::size_t i = index + 1; i > 0; i = (i - 1) / 26) label.insert(label.begin(), static_cast<char>('A' + (i - 1) % 26));
  return label;
}

// A yaw for tables and CSV: rounded to 1e-6 degrees, since a yaw read back
// from a simulated state carries rounding noise (1e-32 for 0 would read as a real angle).
std::string yawText(double yaw) { return adroit::shortNumber(std::round(yaw * 1e6) / 1e6 + 0.0); }

// Yaws as one CSV-safe field: "0 12.5 90".
std::string yawList(const std::vector<double>& yaws) {
  std::string out;
  for (double y : yaws) out += (out.empty() ? "" : " ") + yawText(y);
  return out;
}

std::string percent(int successes, int trials) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f", trials > 0 ? 100.0 * successes / trials : 0.0);
  return text;
}

// ---------------------------------------------------------------------------------------------
// Options.

struct Options {
  std::string task = "pickup", tasks_dir, scene_file, out = "pickup_eval", cross_validate, plot_script;
  std::vector<std::pair<std::string, std::string>> policies;  // name, path
  std::vector<std::string> demo_sources;                      // files or directories
  std::vector<std::pair<std::string, double>> require;        // name, min percent
  double sweep_step = 2, trial_noise = 0.02;
  long long random = 100, seed = 1, workers = 0, trials = 5;
  bool strict = false, plot = true;
};

std::vector<std::string> splitCommas(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, ',');)
    if (!item.empty()) out.push_back(item);
  return out;
}

// Reads argv through adroit::CommandLine (an unknown option or a malformed number: its message
// and the usage, exit 2).
Options parseOptions(int argc, char** argv) {
  Options o;
  adroit::CommandLine args(argc, argv, kUsage);
  while (args.next()) {
    if (args.is("--task")) o.task = args.text();
    else if (args.is("--policy")) o.policies.push_back(splitAssignment("--policy", args.text()));
    else if (args.is("--replay-demos"))
      for (const auto& s : splitCommas(args.text())) o.demo_sources.push_back(s);
    else if (args.is("--sweep-step")) o.sweep_step = args.number();
    else if (args.is("--random")) o.random = args.integer();
    else if (args.is("--seed")) o.seed = args.integer();
    else if (args.is("--workers")) o.workers = args.integer();
    else if (args.is("--out")) o.out = args.text();
    else if (args.is("--cross-validate")) o.cross_validate = args.text();
    else if (args.is("--trials")) o.trials = args.integer();
    else if (args.is("--trial-noise")) o.trial_noise = args.number();
    else if (args.is("--require")) o.require.push_back(parseRequirement(args.text()));
    else if (args.is("--strict")) o.strict = true;
    else if (args.is("--tasks-dir")) o.tasks_dir = args.text();
    else if (args.is("--scene-file")) o.scene_file = args.text();
    else if (args.is("--plot-script")) o.plot_script = args.text();
    else if (args.is("--no-plot")) o.plot = false;
    else args.unknown();
  }
  return o;
}

// Ranges and combinations; InputError with the first problem.
void checkOptions(const Options& o) {
  if (o.policies.empty() && o.demo_sources.empty()) throw InputError("nothing to evaluate: give --policy or --replay-demos");
  if (!(o.sweep_step > 0 && o.sweep_step <= 90))
    throw InputError("--sweep-step must be in (0, 90] degrees, got " + adroit::shortNumber(o.sweep_step));
  if (o.random < 1 || o.random > 100000)
    throw InputError("--random must be in [1, 100000], got " + std::to_string(o.random));
  if (o.trials < 1 || o.trials > 1000) throw InputError("--trials must be in [1, 1000], got " + std::to_string(o.trials));
  if (!(o.trial_noise >= 0 && o.trial_noise <= 1))
    throw InputError("--trial-noise must be a fraction of each joint's range in [0, 1], got " + adroit::shortNumber(o.trial_noise));
  if (o.workers < 0 || o.workers > 1024) throw InputError("--workers must be in [0, 1024], got " + std::to_string(o.workers));
  if (o.seed < 0) throw InputError("--seed must not be negative, got " + std::to_string(o.seed));
  if (o.out.empty()) throw InputError("--out must not be empty");
  for (std::size_t i = 0; i < o.policies.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      if (o.policies[i].first == o.policies[j].first) throw InputError("--policy: name '" + o.policies[i].first + "' given twice");
}

// ---------------------------------------------------------------------------------------------
// The robot, the task and its cost.

struct Setup {
  adroit::TrainingTask task;
  std::string model_path;
  std::unique_ptr<adroit::SimRollouts> sim;
  adroit::StateLayout layout;
  adroit::ObjectGeometry geometry;
  std::unique_ptr<adroit::TrajectoryCost> cost;
};

std::string tasksDirectory(const Options& o) {
  if (!o.tasks_dir.empty()) return o.tasks_dir;
  return adroit::description::packageShareDir("adroit_learning", "config/tasks/pickup.yaml") + "/config/tasks";
}

// The task (with the pickup criterion and a tube), its scene on `workers` SimRollouts workers,
// the state layout and the cost. InputError for anything that stops the evaluation.
Setup makeSetup(const Options& o) {
  Setup s;
  try {
    s.task = adroit::findTrainingTask(tasksDirectory(o), o.task);
    if (!s.task.pickupSuccessCriterion())
      throw InputError("task '" + o.task + "' is not a pickup task (success_criterion: pickup)");
    s.model_path = !o.scene_file.empty()
                       ? o.scene_file
                       : adroit::description::sceneFile(adroit::description::descriptionShareDir(), s.task.scene, false);
    adroit::driver::SimConfig config;
    config.model_path = s.model_path;
    config.mode = adroit::driver::ActuationMode::kPneumatic;
    s.sim = std::make_unique<adroit::SimRollouts>(config, static_cast<int>(o.workers));
    s.layout = adroit::StateLayout(s.task, s.sim->jointNames(), s.sim->cylinderNames(), s.sim->hasObject());
    s.geometry = s.sim->objectGeometry();
    if (!s.geometry.valid()) throw InputError(s.model_path + ": no capsule or cylinder object (body 'object') to pick up");
    s.cost = std::make_unique<adroit::TrajectoryCost>(s.task, s.layout, s.sim->initialState(s.task, s.layout), s.geometry);
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(e.what());
  }
  return s;
}

// ---------------------------------------------------------------------------------------------
// Policies under evaluation.

// The control ticks' action() times (s) of one policy, from every worker.
class TimingSink {
 public:
  void add(const std::vector<double>& seconds) {
    std::lock_guard<std::mutex> lock(mutex_);
    seconds_.insert(seconds_.end(), seconds.begin(), seconds.end());
  }
  std::vector<double> seconds() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return seconds_;
  }

 private:
  mutable std::mutex mutex_;
  std::vector<double> seconds_;
};

// Times every action() of the policy it wraps (one rollout's policy, one worker's thread) and
// hands the times to the sink when the rollout ends.
class TimedPolicy : public adroit::Policy {
 public:
  TimedPolicy(std::unique_ptr<adroit::Policy> inner, TimingSink& sink, int ticks) : inner_(std::move(inner)), sink_(sink) {
    seconds_.reserve(static_cast<std::size_t>(std::max(0, ticks)));
  }
  ~TimedPolicy() override { sink_.add(seconds_); }
  std::string kind() const override { return inner_->kind(); }
  int horizon() const override { return inner_->horizon(); }
  void start(const Eigen::Ref<const Eigen::VectorXd>& x0) override { inner_->start(x0); }
  void action(int t, const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& touch,
              Eigen::Ref<Eigen::VectorXd> u) override {
    const auto begin = std::chrono::steady_clock::now();
    inner_->action(t, x, touch, u);
    seconds_.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count());
  }
  std::string mismatch(const std::vector<std::string>& joints, const std::vector<std::string>& cylinders,
                       const std::vector<std::string>& touch, const adroit::StateLayout& layout) const override {
    return inner_->mismatch(joints, cylinders, touch, layout);
  }

 private:
  std::unique_ptr<adroit::Policy> inner_;
  TimingSink& sink_;
  std::vector<double> seconds_;
};

struct TrialResult {
  double yaw = 0;
  bool success = false;
  double cost = kNaN, selected_yaw = kNaN;
  std::string failure;
};

struct Evaluated {
  std::string name, path, kind;
  std::function<std::unique_ptr<adroit::Policy>()> make;  // a fresh copy per rollout
  std::vector<double> trained_yaws;                       // marked in the sweep plot
  std::vector<double> library_yaws;                       // a library's entries (selected_yaw)
  std::unique_ptr<TimingSink> timing = std::make_unique<TimingSink>();
  std::vector<TrialResult> sweep, random;
  std::vector<std::vector<TrialResult>> cross;  // per condition
};

// A factory of copies of `prototype` (TVLG and library copies share their files; a network's
// copy is deep), or nullptr for a kind this program cannot copy.
template <class Kind>
std::function<std::unique_ptr<adroit::Policy>()> copier(const std::shared_ptr<adroit::Policy>& prototype) {
  const auto typed = std::dynamic_pointer_cast<Kind>(prototype);
  if (!typed) return nullptr;
  return [typed] { return std::unique_ptr<adroit::Policy>(std::make_unique<Kind>(*typed)); };
}

// The `initial_object_yaw` a TVLG file's header records, when it does (the trainer's files name
// their task, not yet its yaw); NaN otherwise.
double recordedTrainedYaw(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  for (int i = 0; i < 200 && std::getline(in, line) && line != "matrices"; ++i) {
    std::istringstream words(line);
    std::string key;
    double yaw = kNaN;
    if (words >> key && key == "initial_object_yaw" && words >> yaw && yaw >= 0 && yaw < 180) return yaw;
  }
  return kNaN;
}

// Checks that a loaded policy fits the task and robot; InputError naming it otherwise.
void checkPolicy(const adroit::Policy& policy, const adroit::PolicyOrigin& origin, const std::string& name,
                 const Setup& s) {
  const std::string who = "policy '" + name + "'";
  if (origin.task != s.task.name)
    throw InputError(who + " is a policy of task '" + origin.task + "', the evaluation runs task '" + s.task.name + "'");
  if (std::abs(origin.control_dt - s.task.control_dt) > 1e-9)
    throw InputError(who + " runs every " + adroit::shortNumber(origin.control_dt) + " s, the task every " +
                     adroit::shortNumber(s.task.control_dt) + " s");
  const std::string problem =
      policy.mismatch(s.sim->jointNames(), s.sim->cylinderNames(), s.sim->touchNames(), s.layout);
  if (!problem.empty()) throw InputError(who + ": " + problem);
  if (policy.horizon() > 0 && policy.horizon() < s.task.horizon)
    throw InputError(who + " is defined for " + std::to_string(policy.horizon()) + " steps, the task runs " +
                     std::to_string(s.task.horizon));
}

// Loads --policy NAME=PATH, checks it and makes its factory.
Evaluated loadEvaluated(const std::string& name, const std::string& path, const Setup& s) {
  adroit::PolicyContext context;
  // By value: the factory of another reader's kind keeps the context.
  context.object_geometry = [task = s.task.name, scene = s.task.scene, geometry = s.geometry](const std::string& wanted) {
    if (wanted != scene)
      throw adroit::PolicyFileError("a library of scene '" + wanted + "'; task '" + task + "' runs in '" + scene + "'");
    return geometry;
  };
  adroit::PolicyOrigin origin;
  std::shared_ptr<adroit::Policy> prototype;
  try {
    prototype = adroit::loadPolicy(path, context, &origin);
  } catch (const std::exception& e) {
    throw InputError("policy '" + name + "': " + e.what());
  }
  checkPolicy(*prototype, origin, name, s);
  Evaluated p;
  p.name = name, p.path = path, p.kind = prototype->kind();
  p.make = copier<adroit::TvlgPolicy>(prototype);
  if (!p.make) p.make = copier<adroit::LibraryPolicy>(prototype);
  if (!p.make) p.make = copier<adroit::NetworkPolicy>(prototype);
  if (!p.make) p.make = [path, context] { return adroit::loadPolicy(path, context); };  // another reader's kind
  if (const auto* library = dynamic_cast<const adroit::LibraryPolicy*>(prototype.get()))
    p.library_yaws = p.trained_yaws = library->library().yaws();
  else if (p.kind == "tvlg" && !std::isnan(recordedTrainedYaw(path)))
    p.trained_yaws = {recordedTrainedYaw(path)};
  return p;
}

// Every *.txt of a directory (sorted), or the file itself.
std::vector<std::string> demoFiles(const std::vector<std::string>& sources) {
  std::vector<std::string> files;
  for (const auto& source : sources) {
    std::error_code ec;
    if (!std::filesystem::is_directory(source, ec)) {
      files.push_back(source);
      continue;
    }
    std::vector<std::string> in_dir;
    for (const auto& entry : std::filesystem::directory_iterator(source, ec))
      if (entry.path().extension() == ".txt") in_dir.push_back(entry.path().string());
    if (ec) throw InputError("--replay-demos: cannot list " + source + ": " + ec.message());
    if (in_dir.empty()) throw InputError("--replay-demos: no *.txt demonstration in " + source);
    std::sort(in_dir.begin(), in_dir.end());
    files.insert(files.end(), in_dir.begin(), in_dir.end());
  }
  return files;
}

// One open-loop replay per demonstration file, named demo_<initial tube yaw>.
std::vector<Evaluated> loadDemoReplays(const std::vector<std::string>& sources, const Setup& s,
                                       std::vector<std::string>& names) {
  std::vector<Evaluated> out;
  for (const auto& file : demoFiles(sources)) {
    Evaluated p;
    try {
      const adroit::Demonstration demo = adroit::readDemonstrationFile(file);
      auto policy = std::make_shared<const adroit::TvlgPolicy>(adroit::demonstrationReplayPolicy(demo, s.task, s.layout), file);
      const double yaw = adroit::tubeYawFromState(demo.x.col(0), s.layout, s.geometry);
      p.name = uniqueName(demoLabel(yaw), names);
      p.trained_yaws = {yaw};
      p.make = [policy] { return std::unique_ptr<adroit::Policy>(std::make_unique<adroit::TvlgPolicy>(*policy)); };
    } catch (const std::exception& e) {
      throw InputError(std::string("--replay-demos: ") + e.what());
    }
    p.path = file, p.kind = "tvlg";
    names.push_back(p.name);
    out.push_back(std::move(p));
  }
  return out;
}

std::vector<Evaluated> loadAll(const Options& o, const Setup& s) {
  std::vector<Evaluated> all;
  std::vector<std::string> names;
  for (const auto& [name, path] : o.policies) {
    all.push_back(loadEvaluated(name, path, s));
    names.push_back(name);
  }
  for (auto& demo : loadDemoReplays(o.demo_sources, s, names)) all.push_back(std::move(demo));
  for (const auto& [name, min] : o.require)
    if (std::find(names.begin(), names.end(), name) == names.end())
      throw InputError("--require " + name + ": no policy of that name (policies: " + [&] {
        std::string list;
        for (const auto& n : names) list += (list.empty() ? "" : " ") + n;
        return list;
      }() + ")");
  return all;
}

// The cross-validation conditions: the library's yaws (read with readPolicyLibrary: the same
// checks as a policy library).
std::vector<double> crossValidationYaws(const Options& o, const Setup& s) {
  if (o.cross_validate.empty()) return {};
  try {
    const adroit::PolicyLibrary library = adroit::readPolicyLibrary(o.cross_validate);
    if (library.task != s.task.name)
      throw InputError("--cross-validate: " + o.cross_validate + " is a library of task '" + library.task + "', not '" +
                       s.task.name + "'");
    return library.yaws();
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(std::string("--cross-validate: ") + e.what());
  }
}

// ---------------------------------------------------------------------------------------------
// Rollouts.

// The trial's outcome: the task's success criterion at T, the cost, and for a library the yaw
// of the local policy it chose (the entry nearest the tube's yaw in x_0, as LibraryPolicy::start).
TrialResult judge(const adroit::RolloutResult& r, double yaw, const Evaluated& p, const Setup& s) {
  TrialResult t;
  t.yaw = yaw;
  if (!r.ok) {
    t.failure = "rollout failed: " + r.error;
    return t;
  }
  const adroit::TaskOutcome outcome = s.cost->outcome(r.sample);
  t.success = outcome.success, t.cost = outcome.cost, t.failure = outcome.failure;
  if (!p.library_yaws.empty()) {
    try {
      const int i = adroit::nearestPolicyIndex(p.library_yaws, adroit::tubeYawFromState(r.sample.x.col(0), s.layout, s.geometry));
      if (i >= 0) t.selected_yaw = p.library_yaws[i];
    } catch (const std::exception&) {
      // A vertical or non-finite tube at x_0: the library refused it too (the rollout failed).
    }
  }
  return t;
}

// Runs `p` once per (yaw, joint offset), a fresh timed copy per rollout.
std::vector<TrialResult> runTrials(Evaluated& p, const Setup& s, const std::vector<double>& yaws,
                                   const std::vector<std::vector<double>>& offsets = {}) {
  std::vector<adroit::RolloutRequest> requests(yaws.size());
  for (std::size_t i = 0; i < yaws.size(); ++i) {
    requests[i].object_yaw_deg = yaws[i];
    if (i < offsets.size()) requests[i].joint_offset = offsets[i];
  }
  TimingSink& sink = *p.timing;
  const auto make = p.make;
  const int ticks = s.task.horizon;
  const adroit::PolicyFactory factory = [make, &sink, ticks] {
    return std::unique_ptr<adroit::Policy>(std::make_unique<TimedPolicy>(make(), sink, ticks));
  };
  const std::atomic<bool> no_cancel{false};
  const auto results = s.sim->runPolicy(s.task, s.layout, factory, requests, s.task.horizon, no_cancel);
  std::vector<TrialResult> trials;
  for (std::size_t i = 0; i < results.size(); ++i) trials.push_back(judge(results[i], yaws[i], p, s));
  return trials;
}

int successes(const std::vector<TrialResult>& trials) {
  return static_cast<int>(std::count_if(trials.begin(), trials.end(), [](const TrialResult& t) { return t.success; }));
}

void progress(const std::string& phase, const Evaluated& p, const std::vector<TrialResult>& trials, double seconds) {
  std::printf("  %-8s %-24s %4d/%-4zu successful  %7.1f s\n", phase.c_str(), p.name.c_str(), successes(trials), trials.size(),
              seconds);
  std::fflush(stdout);
}

// (b) and (c) for every policy; (a) when there are conditions. The same random yaws and
// joint offsets for every policy.
void evaluateAll(std::vector<Evaluated>& policies, const Setup& s, const Options& o, const std::vector<double>& conditions) {
  const std::vector<double> sweep = yawGrid(o.sweep_step), random = randomYaws(static_cast<int>(o.random), o.seed);
  adroit::NormalNoise offset_rng(static_cast<std::uint64_t>(o.seed) ^ 0x70696b7570ULL);  // its own stream
  std::vector<std::vector<double>> offsets;
  for (long long k = 0; k < o.trials; ++k)
    offsets.push_back(adroit::initialStateOffsets(offset_rng, s.sim->jointRanges(), o.trial_noise));
  for (Evaluated& p : policies) {
    adroit::Stopwatch watch;
    p.sweep = runTrials(p, s, sweep);
    progress("sweep", p, p.sweep, watch.elapsed());
    watch.restart();
    p.random = runTrials(p, s, random);
    progress("random", p, p.random, watch.elapsed());
    for (std::size_t c = 0; c < conditions.size(); ++c) {
      watch.restart();
      p.cross.push_back(runTrials(p, s, std::vector<double>(offsets.size(), conditions[c]), offsets));
      progress("cond " + conditionLabel(c), p, p.cross.back(), watch.elapsed());
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Summary, files, table, RESULT lines.

struct Summary {
  int sweep_ok = 0, sweep_n = 0, random_ok = 0, random_n = 0;
  Interval ci;
  double random_cost = kNaN, p50_ms = kNaN, p99_ms = kNaN;
  std::size_t ticks = 0;
};

double meanFiniteCost(const std::vector<TrialResult>& trials) {
  double sum = 0;
  int n = 0;
  for (const auto& t : trials)
    if (std::isfinite(t.cost)) sum += t.cost, ++n;
  return n > 0 ? sum / n : kNaN;
}

Summary summarise(const Evaluated& p) {
  Summary s;
  s.sweep_ok = successes(p.sweep), s.sweep_n = static_cast<int>(p.sweep.size());
  s.random_ok = successes(p.random), s.random_n = static_cast<int>(p.random.size());
  s.ci = wilsonInterval(s.random_ok, s.random_n);
  s.random_cost = meanFiniteCost(p.random);
  const std::vector<double> seconds = p.timing->seconds();
  s.ticks = seconds.size();
  if (!seconds.empty()) s.p50_ms = adroit::percentile(seconds, 50) * 1e3, s.p99_ms = adroit::percentile(seconds, 99) * 1e3;
  return s;
}

std::string trialCsv(const std::vector<TrialResult>& trials, const Evaluated& p, bool with_index) {
  std::ostringstream out;
  for (std::size_t i = 0; i < trials.size(); ++i) {
    const TrialResult& t = trials[i];
    out << csvField(p.name) << ',' << (with_index ? std::to_string(i) + "," : "") << adroit::shortNumber(t.yaw) << ','
        << (t.success ? 1 : 0) << ',' << numberField(t.cost) << ',' << csvField(t.failure) << ','
        << numberField(t.selected_yaw) << '\n';
  }
  return out.str();
}

void writeTrialFiles(const std::vector<Evaluated>& policies, const std::string& out) {
  std::string sweep = "policy,yaw_deg,success,cost,failure,selected_yaw\n";
  std::string random = "policy,trial,yaw_deg,success,cost,failure,selected_yaw\n";
  for (const Evaluated& p : policies) {
    sweep += trialCsv(p.sweep, p, false);
    random += trialCsv(p.random, p, true);
  }
  adroit::writeFileAtomically(out + "/sweep.csv", sweep);
  adroit::writeFileAtomically(out + "/random.csv", random);
}

std::string ciText(const Summary& s) {
  char text[64];
  std::snprintf(text, sizeof text, "[%.1f, %.1f]", 100 * s.ci.low, 100 * s.ci.high);
  return text;
}

std::string msText(double ms) {
  if (std::isnan(ms)) return "-";
  char text[32];
  std::snprintf(text, sizeof text, "%.4f", ms);
  return text;
}

void writeSummaryFiles(const std::vector<Evaluated>& policies, const std::vector<Summary>& sums, const std::string& out) {
  std::ostringstream csv, md;
  csv << "policy,kind,path,trained_yaws,sweep_successes,sweep_trials,sweep_success_percent,random_successes,random_trials,"
         "random_success_percent,random_ci_low_percent,random_ci_high_percent,random_mean_cost,inference_ticks,"
         "inference_p50_ms,inference_p99_ms\n";
  md << "| policy | kind | trained yaw (deg) | sweep success | random success [95 % CI] | mean cost (random) | "
        "inference p50 / p99 (ms) |\n|---|---|---|---|---|---|---|\n";
  for (std::size_t i = 0; i < policies.size(); ++i) {
    const Evaluated& p = policies[i];
    const Summary& s = sums[i];
    csv << csvField(p.name) << ',' << p.kind << ',' << csvField(p.path) << ',' << yawList(p.trained_yaws) << ','
        << s.sweep_ok << ',' << s.sweep_n << ',' << percent(s.sweep_ok, s.sweep_n) << ',' << s.random_ok << ','
        << s.random_n << ',' << percent(s.random_ok, s.random_n) << ',' << numberField(100 * s.ci.low) << ','
        << numberField(100 * s.ci.high) << ',' << numberField(s.random_cost) << ',' << s.ticks << ','
        << numberField(s.p50_ms) << ',' << numberField(s.p99_ms) << '\n';
    md << "| " << p.name << " | " << p.kind << " | " << (p.trained_yaws.empty() ? "-" : yawList(p.trained_yaws)) << " | "
       << percent(s.sweep_ok, s.sweep_n) << " % (" << s.sweep_ok << "/" << s.sweep_n << ") | "
       << percent(s.random_ok, s.random_n) << " % " << ciText(s) << " | " << numberField(s.random_cost) << " | "
       << msText(s.p50_ms) << " / " << msText(s.p99_ms) << " |\n";
  }
  adroit::writeFileAtomically(out + "/summary.csv", csv.str());
  adroit::writeFileAtomically(out + "/summary.md", md.str());
}

// The table of fig. 11.12: policies x (conditions + random); also printed.
std::string crossValidationTable(const std::vector<Evaluated>& policies, const std::vector<Summary>& sums,
                                 const std::vector<double>& conditions, const Options& o) {
  std::ostringstream md;
  md << "| policy |";
  for (std::size_t c = 0; c < conditions.size(); ++c)
    md << ' ' << conditionLabel(c) << " (" << yawText(conditions[c]) << " deg) |";
  md << " random |\n|---|";
  for (std::size_t c = 0; c <= conditions.size(); ++c) md << "---|";
  md << '\n';
  for (std::size_t i = 0; i < policies.size(); ++i) {
    md << "| " << policies[i].name << " |";
    for (const auto& trialsAt : policies[i].cross)
      md << ' ' << percent(successes(trialsAt), static_cast<int>(trialsAt.size())) << " % |";
    md << ' ' << percent(sums[i].random_ok, sums[i].random_n) << " % |\n";
  }
  md << "\n" << o.trials << " trials per condition (initial joints offset uniformly within +-" << adroit::shortNumber(50 * o.trial_noise)
     << " % of each joint's range), "
     << (sums.empty() ? 0 : sums.front().random_n) << " random yaws.\n";
  return md.str();
}

void writeCrossValidation(const std::vector<Evaluated>& policies, const std::vector<Summary>& sums,
                          const std::vector<double>& conditions, const Options& o) {
  std::ostringstream csv;
  csv << "policy,condition,yaw_deg,trials,successes,success_percent\n";
  for (std::size_t i = 0; i < policies.size(); ++i) {
    const Evaluated& p = policies[i];
    for (std::size_t c = 0; c < p.cross.size(); ++c) {
      const int n = static_cast<int>(p.cross[c].size()), ok = successes(p.cross[c]);
      csv << csvField(p.name) << ',' << conditionLabel(c) << ',' << yawText(conditions[c]) << ',' << n << ','
          << ok << ',' << percent(ok, n) << '\n';
    }
    csv << csvField(p.name) << ",random,," << sums[i].random_n << ',' << sums[i].random_ok << ','
        << percent(sums[i].random_ok, sums[i].random_n) << '\n';
  }
  adroit::writeFileAtomically(o.out + "/cross_validation.csv", csv.str());
  adroit::writeFileAtomically(o.out + "/cross_validation.md", crossValidationTable(policies, sums, conditions, o));
}

// plot_pickup_eval.py <out>: sweep.png and random.png. A failure is one line.
void plot(const Options& o) {
  if (!o.plot) return;
  std::string script = o.plot_script;
  try {
    if (script.empty())
      script = adroit::description::packageShareDir("adroit_learning", "scripts/plot_pickup_eval.py") +
               "/scripts/plot_pickup_eval.py";
  } catch (const std::exception& e) {
    std::printf("(plots not written: %s)\n", e.what());
    return;
  }
  adroit::ProgramOptions options;
  options.timeout_s = 120;
  options.capture_output = true;
  options.merge_stderr = true;
  const adroit::ProgramResult r = adroit::runProgram({"/usr/bin/python3", script, o.out}, options);
  if (r.ok()) return;
  std::string last = r.output;
  while (!last.empty() && last.back() == '\n') last.pop_back();
  last = last.substr(last.find_last_of('\n') == std::string::npos ? 0 : last.find_last_of('\n') + 1);
  std::printf("(plots not written: %s%s)\n", r.describe().c_str(), last.empty() ? "" : (": " + last).c_str());
}

void printTable(const std::vector<Evaluated>& policies, const std::vector<Summary>& sums, int workers) {
  std::printf("\n%-24s %-8s %-16s %14s %26s %12s %22s\n", "policy", "kind", "trained yaw", "sweep success",
              "random success [95% CI]", "mean cost", "inference p50/p99 ms");
  for (std::size_t i = 0; i < policies.size(); ++i) {
    const Evaluated& p = policies[i];
    const Summary& s = sums[i];
    const std::string sweep = percent(s.sweep_ok, s.sweep_n) + " % (" + std::to_string(s.sweep_ok) + "/" +
                              std::to_string(s.sweep_n) + ")";
    const std::string random = percent(s.random_ok, s.random_n) + " % " + ciText(s);
    const std::string timing = msText(s.p50_ms) + " / " + msText(s.p99_ms);
    std::printf("%-24s %-8s %-16s %14s %26s %12s %22s\n", p.name.c_str(), p.kind.c_str(),
                p.trained_yaws.empty() ? "-" : yawList(p.trained_yaws).substr(0, 16).c_str(), sweep.c_str(),
                random.c_str(), numberField(s.random_cost).c_str(), timing.c_str());
  }
  std::printf("(inference: each control tick's action(), timed while %d workers shared %u hardware threads; "
              "--workers 1 gives an uncontended figure)\n",
              workers, std::thread::hardware_concurrency());
}

// The most any selection among the local policies can reach on the random yaws: the share of
// trials at which at least one "tvlg" policy (a local policy or a demonstration replay) succeeds.
// Nearest neighbour deploys one of them per trial, so it cannot exceed this; the networks learn
// from their rollouts. NaN when the run has no such policy or no random trials.
double localPolicyCeiling(const std::vector<Evaluated>& policies) {
  std::size_t trials = 0;
  for (const Evaluated& p : policies)
    if (p.kind == "tvlg") trials = std::max(trials, p.random.size());
  if (trials == 0) return kNaN;
  int covered = 0;
  for (std::size_t i = 0; i < trials; ++i)
    covered += std::any_of(policies.begin(), policies.end(), [&](const Evaluated& p) {
      return p.kind == "tvlg" && i < p.random.size() && p.random[i].success;
    });
  return 100.0 * covered / static_cast<double>(trials);
}

// The ceiling as the bound of the same run, against the highest --require rate (none without
// --require); true when the ceiling leaves that rate within reach.
bool printCeiling(const std::vector<Evaluated>& policies, const Options& o) {
  const double ceiling = localPolicyCeiling(policies);
  if (std::isnan(ceiling) || o.require.empty()) return true;
  double highest = 0;
  for (const auto& r : o.require) highest = std::max(highest, r.second);
  std::printf("(bound: the random yaws at which any local policy or demonstration replay of this run succeeds; "
              "nearest neighbour deploys one of them per yaw)\n");
  std::printf("%s\n", adroit::resultLine("adroit_learning", "pickup_local_policy_ceiling", ceiling, "%", ">=", highest).c_str());
  return ceiling >= highest;
}

// RESULT lines; true when every targeted figure passes.
bool printResults(const std::vector<Evaluated>& policies, const std::vector<Summary>& sums, const Options& o) {
  bool all_pass = true;
  std::printf("\n");
  for (std::size_t i = 0; i < policies.size(); ++i) {
    const double rate = sums[i].random_n > 0 ? 100.0 * sums[i].random_ok / sums[i].random_n : 0.0;
    const auto req = std::find_if(o.require.begin(), o.require.end(), [&](const auto& r) { return r.first == policies[i].name; });
    if (req == o.require.end()) {
      std::printf("INFO adroit_learning/pickup_random_success/%s %.4g %% (no target; --require %s=MIN sets one)\n",
                  policies[i].name.c_str(), rate, policies[i].name.c_str());
      continue;
    }
    all_pass = all_pass && rate >= req->second;
    std::printf("%s\n", adroit::resultLine("adroit_learning", "pickup_random_success/" + policies[i].name, rate, "%", ">=",
                                           req->second).c_str());
  }
  for (std::size_t i = 0; i < policies.size(); ++i) {
    if (policies[i].kind != "network" || std::isnan(sums[i].p99_ms)) continue;
    all_pass = all_pass && sums[i].p99_ms <= kInferenceTargetMs;
    std::printf("%s\n", adroit::resultLine("adroit_learning", "pickup_inference_p99/" + policies[i].name, sums[i].p99_ms,
                                           "ms", "<=", kInferenceTargetMs).c_str());
  }
  return printCeiling(policies, o) && all_pass;
}

// Everything that can refuse the input, before any rollout.
struct Prepared {
  Setup setup;
  std::vector<Evaluated> policies;
  std::vector<double> conditions;
};

Prepared prepare(const Options& o) {
  checkOptions(o);
  Prepared p{makeSetup(o), {}, {}};
  p.policies = loadAll(o, p.setup);
  p.conditions = crossValidationYaws(o, p.setup);
  std::error_code ec;
  std::filesystem::create_directories(o.out, ec);
  if (ec || !std::filesystem::is_directory(o.out)) throw InputError("--out " + o.out + ": cannot create the directory" + (ec ? ": " + ec.message() : ""));
  return p;
}

void printSetup(const Prepared& p, const Options& o) {
  const Setup& s = p.setup;
  std::printf("pickup_eval: task %s (scene %s: %s), T %d x %.0f ms, %d workers; %zu policies; sweep every %s deg (%zu "
              "yaws), %lld random yaws (seed %lld)",
              s.task.name.c_str(), s.task.scene.c_str(), s.model_path.c_str(), s.task.horizon, s.task.control_dt * 1e3,
              s.sim->workers(), p.policies.size(), adroit::shortNumber(o.sweep_step).c_str(), yawGrid(o.sweep_step).size(),
              o.random, o.seed);
  if (!p.conditions.empty())
    std::printf("; cross-validation: %zu conditions x %lld trials (initial joints within +-%s %% of each range)",
                p.conditions.size(), o.trials, adroit::shortNumber(50 * o.trial_noise).c_str());
  std::printf("\n");
  std::fflush(stdout);
}

}  // namespace

#ifndef PICKUP_EVAL_NO_MAIN
int main(int argc, char** argv) {
  adroit::registerNetworkPolicyReader();
  Options options;
  std::unique_ptr<Prepared> prepared;
  try {
    options = parseOptions(argc, argv);
    prepared = std::make_unique<Prepared>(prepare(options));
  } catch (const InputError& e) {
    std::fprintf(stderr, "pickup_eval: %s\n", e.what());
    return 2;
  }
  printSetup(*prepared, options);
  std::vector<Evaluated>& policies = prepared->policies;
  evaluateAll(policies, prepared->setup, options, prepared->conditions);
  std::vector<Summary> sums;
  for (const Evaluated& p : policies) sums.push_back(summarise(p));
  try {
    writeTrialFiles(policies, options.out);
    writeSummaryFiles(policies, sums, options.out);
    if (!prepared->conditions.empty()) writeCrossValidation(policies, sums, prepared->conditions, options);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pickup_eval: %s\n", e.what());
    return 1;
  }
  plot(options);
  printTable(policies, sums, prepared->setup.sim->workers());
  if (!prepared->conditions.empty())
    std::printf("\ncross-validation (fig. 11.12):\n%s",
                crossValidationTable(policies, sums, prepared->conditions, options).c_str());
  std::printf("\nwritten to %s/\n", options.out.c_str());
  const bool pass = printResults(policies, sums, options);
  return options.strict && !pass ? 1 : 0;
}
#endif
