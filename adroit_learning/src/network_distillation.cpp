#include "adroit_learning/network_distillation.h"

#include <adroit_core/number_text.h>
#include <adroit_core/normal_noise.h>
#include <adroit_learning/tvlg_policy.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <mutex>
#include <utility>

namespace adroit {

namespace {

constexpr double kMaxVolts = 5.0;  // the valves' range, as StateLayout::command and NetworkPolicy clamp
const double kNaN = std::numeric_limits<double>::quiet_NaN();

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// splitmix64 of (seed, stream): independent seeds for the rounds from one user seed.
std::uint64_t mixSeed(std::uint64_t seed, std::uint64_t stream) {
  std::uint64_t z = seed + 0x9e3779b97f4a7c15ULL * (stream + 1);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

std::string countProblem(const char* what, long long count) {
  if (count >= 1 && count <= kMaxDistillationRollouts) return "";
  return std::string(what) + " must be in [1, " + std::to_string(kMaxDistillationRollouts) + "], got " +
         std::to_string(count);
}

// Samples gathered column by column, appended to a dataset at the end.
class Columns {
 public:
  Columns(const NetworkInput& input, int nu) : input_(input), nu_(nu), u_(nu), zero_noise_(Eigen::VectorXd::Zero(nu)) {}

  // Input at (x_t, touch_t); label: the local controller's mean action at step t in x_t.
  //
  // The mean, not the command the rollout executed: the executed command is the mean plus the
  // exploration noise L_t noise_t, drawn independently of the state. Regressing on it would fit
  // the same mean in expectation but with the noise as label variance (C_t is as large as the
  // actions' spread for the early controllers), slowing and blurring the fit; and the network
  // is to reproduce the controller, not its exploration. The noise still does its job through
  // the states: the rollouts visit a neighbourhood of the mean trajectory, where the mean
  // action is the controller's correction, so the network learns feedback and not one path.
  // Clamped to the valve range, as the valves (StateLayout::command) and the network's own
  // output (NetworkPolicy::action) are: beyond it only the clamped value acts.
  void add(const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& touch,
           const LgController& controller, int t, int group) {
    const std::size_t begin = inputs_.size();
    inputs_.resize(begin + static_cast<std::size_t>(input_.size()));
    input_.fill(x, touch, inputs_.data() + begin);
    controller.action(t, x, zero_noise_, u_);
    for (int i = 0; i < nu_; ++i) actions_.push_back(static_cast<float>(std::clamp(u_[i], -kMaxVolts, kMaxVolts)));
    group_.push_back(group);
  }

  int count() const { return static_cast<int>(group_.size()); }

  void appendTo(NetworkDataset& data) const {
    const Eigen::Index old = data.inputs.cols(), n = count();
    if (old == 0) {
      data.inputs.resize(input_.size(), 0);
      data.actions.resize(nu_, 0);
    }
    data.inputs.conservativeResize(input_.size(), old + n);
    data.actions.conservativeResize(nu_, old + n);
    data.inputs.rightCols(n) = Eigen::Map<const Eigen::MatrixXf>(inputs_.data(), input_.size(), n);
    data.actions.rightCols(n) = Eigen::Map<const Eigen::MatrixXf>(actions_.data(), nu_, n);
    data.group.insert(data.group.end(), group_.begin(), group_.end());
  }

 private:
  const NetworkInput& input_;
  int nu_;
  Eigen::VectorXd u_, zero_noise_;
  std::vector<float> inputs_, actions_;
  std::vector<int> group_;
};

void requireInputFits(const NetworkInput& input, const StateLayout& layout, const RolloutBackend& backend) {
  const int touch = static_cast<int>(backend.touchNames().size());
  if (input.stateSize() != layout.nx() || (input.readsTouch() && input.touchCount() != touch))
    throw std::invalid_argument("distillation: the network input reads a state of " + std::to_string(input.stateSize()) +
                                " and " + std::to_string(input.touchCount()) + " touch sensors, the task gives " +
                                std::to_string(layout.nx()) + " and the robot has " + std::to_string(touch));
}

void requireLibraryFits(const PolicyLibrary& library, const TrainingTask& task, const StateLayout& layout,
                        const RolloutBackend& backend) {
  const std::string problem = libraryProblem(library, task, layout, backend);
  if (!problem.empty()) throw std::invalid_argument("distillation: " + problem);
}

void throwIfCancelled(const std::atomic<bool>& cancel) {
  if (cancel.load()) throw DistillationCancelled();
}

// Counts a result into `stats`; true when its samples are to be kept.
bool countResult(const RolloutResult& result, CollectionStats& stats) {
  ++stats.rollouts;
  if (result.ok) return true;
  if (stats.failed++ == 0) stats.first_failure = result.error;
  stats.groups.push_back(-1);
  return false;
}

}  // namespace

std::string libraryProblem(const PolicyLibrary& library, const TrainingTask& task, const StateLayout& layout,
                           const RolloutBackend& backend) {
  if (library.task != task.name)
    return "the library is of task '" + library.task + "', not '" + task.name + "'";
  if (library.scene != task.scene)
    return "the library is of scene '" + library.scene + "', task '" + task.name + "' runs in '" + task.scene + "'";
  if (library.entries.empty()) return "the library has no policies";
  for (const PolicyLibraryEntry& e : library.entries) {
    const std::string name = e.resolved_path.empty() ? e.path : e.resolved_path;
    if (!e.policy) return name + ": policy not read";
    if (!(std::isfinite(e.yaw_deg) && e.yaw_deg >= 0 && e.yaw_deg < 180))
      return name + ": angle must be in [0, 180) degrees, got " + exactNumber(e.yaw_deg);
    const std::string mismatch =
        TvlgPolicy(e.policy, name).mismatch(backend.jointNames(), backend.cylinderNames(), backend.touchNames(), layout);
    if (!mismatch.empty()) return mismatch;
    const LgController& c = e.policy->controller;
    if (c.nx() != layout.nx() || c.nu() != layout.nu() || c.horizon() < 1)
      return name + ": controller of nx " + std::to_string(c.nx()) + ", nu " + std::to_string(c.nu()) + ", T " +
             std::to_string(c.horizon()) + ", the task needs nx " + std::to_string(layout.nx()) + ", nu " +
             std::to_string(layout.nu()) + " and T >= 1";
    if (e.policy->control_dt != task.control_dt)
      return name + ": control_dt " + exactNumber(e.policy->control_dt) + " s, task '" + task.name + "' has " +
             exactNumber(task.control_dt) + " s";
    if (e.policy->locked_command != layout.locked_command)
      return name + ": locked cylinders held at " + exactNumber(e.policy->locked_command) + " V, task '" + task.name +
             "' holds them at " + exactNumber(layout.locked_command) + " V";
  }
  return "";
}

NetworkDataset collectLocalPolicyData(RolloutBackend& backend, const TrainingTask& task, const StateLayout& layout,
                                      const PolicyLibrary& library, int rollouts_per_policy, const NetworkInput& input,
                                      std::uint64_t seed, CollectionStats* stats, const std::atomic<bool>* cancel) {
  const std::string count = countProblem("rollouts per policy", rollouts_per_policy);
  if (!count.empty()) throw std::invalid_argument("distillation: " + count);
  requireLibraryFits(library, task, layout, backend);
  requireInputFits(input, layout, backend);
  const std::atomic<bool> never{false};
  const std::atomic<bool>& cancelled = cancel ? *cancel : never;
  CollectionStats local;
  CollectionStats& s = stats ? *stats : local;
  s = CollectionStats{};

  NormalNoise rng(seed);
  Columns columns(input, layout.nu());
  for (std::size_t p = 0; p < library.entries.size(); ++p) {
    const PolicyLibraryEntry& entry = library.entries[p];
    const LgController& controller = entry.policy->controller;
    // Its own covariance (no scale) and white noise, from its own initial state.
    std::vector<RolloutRequest> requests(static_cast<std::size_t>(rollouts_per_policy));
    for (RolloutRequest& r : requests) {
      r.noise = smoothedNoise(rng, layout.nu(), controller.horizon(), 0.0);
      r.object_yaw_deg = entry.yaw_deg;
    }
    const std::vector<RolloutResult> results = backend.run(task, layout, controller, requests, cancelled);
    throwIfCancelled(cancelled);
    for (std::size_t i = 0; i < results.size(); ++i) {
      s.yaws.push_back(entry.yaw_deg);
      s.labelled_by.push_back(static_cast<int>(p));
      if (!countResult(results[i], s)) continue;
      const int group = static_cast<int>(p) * rollouts_per_policy + static_cast<int>(i);
      s.groups.push_back(group);
      const RolloutResult& r = results[i];
      for (int t = 0; t < controller.horizon(); ++t) columns.add(r.sample.x.col(t), r.touch.col(t), controller, t, group);
    }
  }
  NetworkDataset data;
  columns.appendTo(data);
  s.samples = columns.count();
  return data;
}

int aggregateOnPolicyData(RolloutBackend& backend, const TrainingTask& task, const StateLayout& layout,
                          const PolicyLibrary& library, const NetworkPolicy& current, NetworkDataset& data, int rollouts,
                          std::uint64_t seed, int steps, CollectionStats* stats, const std::atomic<bool>* cancel) {
  const std::string count = countProblem("DAgger rollouts", rollouts);
  if (!count.empty()) throw std::invalid_argument("distillation: " + count);
  if (steps < 0) throw std::invalid_argument("distillation: DAgger steps must be >= 0, got " + std::to_string(steps));
  requireLibraryFits(library, task, layout, backend);
  const NetworkInput& input = current.input();
  requireInputFits(input, layout, backend);
  const Eigen::Index n = data.inputs.cols();
  if (n > 0 && (data.inputs.rows() != input.size() || data.actions.rows() != layout.nu() || data.actions.cols() != n ||
                static_cast<Eigen::Index>(data.group.size()) != n))
    throw std::invalid_argument("distillation: the dataset (inputs " + std::to_string(data.inputs.rows()) + "x" +
                                std::to_string(n) + ", actions " + std::to_string(data.actions.rows()) + "x" +
                                std::to_string(data.actions.cols()) + ", " + std::to_string(data.group.size()) +
                                " group ids) does not fit the network's " + std::to_string(input.size()) + " inputs and " +
                                std::to_string(layout.nu()) + " actions with one group id per sample");
  const std::atomic<bool> never{false};
  const std::atomic<bool>& cancelled = cancel ? *cancel : never;
  CollectionStats local;
  CollectionStats& s = stats ? *stats : local;
  s = CollectionStats{};

  const std::vector<double> library_yaws = library.yaws();
  NormalNoise rng(seed);
  std::vector<RolloutRequest> requests(static_cast<std::size_t>(rollouts));
  std::vector<double> yaws(requests.size());
  for (std::size_t i = 0; i < requests.size(); ++i) {
    double yaw = i < library_yaws.size() ? library_yaws[i] : 180.0 * rng.uniform();
    if (yaw >= 180.0) yaw = 0.0;  // rounding of 180 * (1 - 2^-53); the same tube pose
    yaws[i] = yaw;
    requests[i].object_yaw_deg = yaw;
  }
  // One copy of the network per rollout (copies are deep; action() is not thread-safe on one).
  // The copies are made on the backend's worker threads, one at a time.
  std::mutex copy_mutex;
  const PolicyFactory make_policy = [&]() -> std::unique_ptr<Policy> {
    const std::lock_guard<std::mutex> lock(copy_mutex);
    return std::make_unique<NetworkPolicy>(current);
  };
  const int run_steps = steps > 0 ? steps : task.horizon;
  const std::vector<RolloutResult> results = backend.runPolicy(task, layout, make_policy, requests, run_steps, cancelled);
  throwIfCancelled(cancelled);

  int next_group = 0;
  for (int g : data.group) next_group = std::max(next_group, g + 1);
  Columns columns(input, layout.nu());
  for (std::size_t i = 0; i < results.size(); ++i) {
    const int nearest = nearestPolicyIndex(library_yaws, yaws[i]);
    s.yaws.push_back(yaws[i]);
    s.labelled_by.push_back(nearest);
    if (!countResult(results[i], s)) continue;
    const int group = next_group++;
    s.groups.push_back(group);
    const RolloutResult& r = results[i];
    const LgController& controller = library.entries[static_cast<std::size_t>(nearest)].policy->controller;
    const int visited = static_cast<int>(r.sample.u.cols());
    for (int t = 0; t < visited; ++t)
      columns.add(r.sample.x.col(t), r.touch.col(t), controller, std::min(t, controller.horizon() - 1), group);
  }
  columns.appendTo(data);
  s.samples = columns.count();
  return s.samples;
}

std::string DistillationSettings::validate() const {
  std::string problem = countProblem("rollouts_per_policy", rollouts_per_policy);
  if (!problem.empty()) return problem;
  if (dagger_rounds < 0 || dagger_rounds > kMaxDaggerRounds)
    return "dagger_rounds must be in [0, " + std::to_string(kMaxDaggerRounds) + "], got " + std::to_string(dagger_rounds);
  if (dagger_rounds > 0) {
    problem = countProblem("dagger_rollouts", dagger_rollouts);
    if (!problem.empty()) return problem;
  }
  if (dagger_steps < 0 || dagger_steps > 1000000)
    return "dagger_steps must be in [0, 1000000] (0 = the task's horizon), got " + std::to_string(dagger_steps);
  problem = spec.validate();
  if (!problem.empty()) return problem;
  return training.validate();
}

double DistillationRound::trainLoss() const { return training.train_loss.empty() ? kNaN : training.train_loss.back(); }
double DistillationRound::heldOutLoss() const {
  return training.held_out_loss.empty() ? kNaN : training.held_out_loss.back();
}

NetworkPolicy distillLibrary(RolloutBackend& backend, const TrainingTask& task, const StateLayout& layout,
                             const PolicyLibrary& library, const DistillationSettings& settings,
                             DistillationReport* report, const DistillationProgressFn& progress,
                             const std::atomic<bool>* cancel) {
  const auto started = std::chrono::steady_clock::now();
  const std::string problem = settings.validate();
  if (!problem.empty()) throw std::invalid_argument("distillation: " + problem);
  requireLibraryFits(library, task, layout, backend);
  const std::vector<std::string> touch = backend.touchNames();
  const NetworkPolicyMetadata metadata = NetworkPolicyMetadata::forLayout(
      layout, touch, settings.observation, task.name, task.scene, task.control_dt);
  const NetworkInput input(settings.observation, layout, static_cast<int>(touch.size()));
  DistillationReport local;
  DistillationReport& rep = report ? *report : local;
  rep = DistillationReport{};

  const auto tell = [&](DistillationProgress::Stage stage, const DistillationRound& round, int epoch = 0,
                        double train = 0, double held_out = 0) {
    if (!progress) return;
    DistillationProgress p;
    p.stage = stage;
    p.round = round.round;
    p.epoch = epoch;
    p.train_loss = train;
    p.held_out_loss = held_out;
    p.summary = &round;
    progress(p);
  };
  const auto train = [&](DistillationRound& round, const NetworkDataset& data) {
    round.dataset_samples = static_cast<int>(data.inputs.cols());
    const auto training_started = std::chrono::steady_clock::now();
    NetworkPolicy policy = trainNetworkPolicy(data, settings.spec, settings.training, metadata, &round.training,
                                              [&](int epoch, double train_loss, double held_out_loss) {
                                                tell(DistillationProgress::Stage::epoch, round, epoch, train_loss,
                                                     held_out_loss);
                                              });
    round.train_seconds = secondsSince(training_started);
    tell(DistillationProgress::Stage::trained, round);
    return policy;
  };

  DistillationRound first;
  auto start = std::chrono::steady_clock::now();
  NetworkDataset data = collectLocalPolicyData(backend, task, layout, library, settings.rollouts_per_policy, input,
                                               settings.seed, &first.collection, cancel);
  first.collect_seconds = secondsSince(start);
  tell(DistillationProgress::Stage::collected, first);
  if (data.inputs.cols() == 0)
    throw std::runtime_error("distillation: none of the " + std::to_string(first.collection.rollouts) +
                             " rollouts of the local policies succeeded; the first failed: " +
                             first.collection.first_failure);
  NetworkPolicy policy = train(first, data);
  rep.rounds.push_back(std::move(first));

  for (int k = 1; k <= settings.dagger_rounds; ++k) {
    DistillationRound round;
    round.round = k;
    start = std::chrono::steady_clock::now();
    const int added = aggregateOnPolicyData(backend, task, layout, library, policy, data, settings.dagger_rollouts,
                                            mixSeed(settings.seed, static_cast<std::uint64_t>(k)), settings.dagger_steps,
                                            &round.collection, cancel);
    round.collect_seconds = secondsSince(start);
    tell(DistillationProgress::Stage::collected, round);
    if (added == 0)
      throw std::runtime_error("distillation: none of the " + std::to_string(round.collection.rollouts) +
                               " network rollouts of DAgger round " + std::to_string(k) +
                               " succeeded; the first failed: " + round.collection.first_failure);
    policy = train(round, data);
    rep.rounds.push_back(std::move(round));
  }
  rep.seconds = secondsSince(started);
  return policy;
}

std::string distillationLossCsv(const DistillationReport& report) {
  std::string csv = "round,epoch,samples,train_loss,held_out_loss,mean_predictor_loss\n";
  char line[160];
  for (const DistillationRound& r : report.rounds) {
    const NetworkTrainingReport& t = r.training;
    for (std::size_t e = 0; e < t.train_loss.size(); ++e) {
      const double held = e < t.held_out_loss.size() ? t.held_out_loss[e] : kNaN;
      std::snprintf(line, sizeof line, "%d,%zu,%d,%.9g,%.9g,%.9g\n", r.round, e + 1, r.dataset_samples,
                    t.train_loss[e], held, t.mean_predictor_held_out_loss);
      csv += line;
    }
  }
  return csv;
}

}  // namespace adroit
