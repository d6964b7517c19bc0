// Distillation of a policy library into a network (thesis 11.6), end to end on the real tube
// scene with a tiny task horizon and a library of two tiny TVLG policies (K = 0, k_t known
// constants, small covariance): the collected data hold every visited state labelled with the
// local policy's mean action, a tiny network distilled from it beats the mean predictor on
// held-out rollouts, a DAgger round adds the network's states labelled by the nearest local
// policy, and train_network_policy (run as a process) trains and refuses bad input in one line.
// Nothing here depends on the tube being picked up, or on the scene's geometry.
#include <adroit_core/run_program.h>
#include <adroit_learning/network_distillation.h>
#include <adroit_learning/sim_rollouts.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace {

constexpr int kT = 5;  // control steps of the tiny task and of the local policies

// Local policy p's mean action entry i at step t: distinct per policy, step and entry.
double localAction(int p, int t, int i) {
  const double a = 0.5 + 0.1 * t + 0.01 * i;
  return p == 0 ? a : -a;
}

std::string freshDirectory(const std::string& name) {
  const std::string dir = std::string(::testing::TempDir()) + "/network_distillation_" + name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

adroit::driver::SimConfig tubeConfig(const std::string& scene) {
  adroit::driver::SimConfig config;
  config.model_path = std::string(ADROIT_MJCF_DIR) + "/" + scene + ".xml";
  config.mode = adroit::driver::ActuationMode::kPneumatic;
  return config;
}

struct Fixture {
  explicit Fixture(const std::string& name)
      : task(shortPickup()), sim(tubeConfig(task.scene), 2),
        layout(task, sim.jointNames(), sim.cylinderNames(), sim.hasObject()), dir(freshDirectory(name)),
        library_path(dir + "/pickup.library") {
    adroit::writePolicyFile(dir + "/yaw000.tvlg", policyFile(0));
    adroit::writePolicyFile(dir + "/yaw010.tvlg", policyFile(1));
    adroit::PolicyLibrary written;
    written.task = task.name;
    written.scene = task.scene;
    // Two yaws close to the task's own start (both within the hand's reach in the thesis' setup).
    written.entries = {{0.0, "yaw000.tvlg", nullptr, ""}, {10.0, "yaw010.tvlg", nullptr, ""}};
    adroit::writePolicyLibrary(library_path, written);
    library = adroit::readPolicyLibrary(library_path);
  }
  static adroit::TrainingTask shortPickup() {
    adroit::TrainingTask t = adroit::findTrainingTask(TASK_DIR, "pickup");
    t.horizon = kT;  // short rollouts keep the test quick
    return t;
  }
  // K = 0, k_t = localAction(p, t, .), covariance 0.01 I (what the trainer writes otherwise).
  adroit::PolicyFile policyFile(int p) const {
    adroit::PolicyFile f;
    f.task = task.name;
    f.scene = task.scene;
    f.state_layout = layout.describe();
    f.control_dt = task.control_dt;
    f.joints = layout.joint_names;
    f.cylinders = layout.cylinder_names;
    for (int c : layout.action_cylinders) f.actions.push_back(layout.cylinder_names[c]);
    f.locked_command = layout.locked_command;
    f.controller = adroit::LgController(layout.nx(), layout.nu(), kT);
    for (int t = 0; t < kT; ++t) {
      for (int i = 0; i < layout.nu(); ++i) f.controller.k[t][i] = localAction(p, t, i);
      f.controller.setCovariance(t, 0.01 * Eigen::MatrixXd::Identity(layout.nu(), layout.nu()));
    }
    return f;
  }
  adroit::NetworkInput input(adroit::ObservationSet set = adroit::ObservationSet::full) const {
    return adroit::NetworkInput(set, layout, static_cast<int>(sim.touchNames().size()));
  }
  adroit::TrainingTask task;
  adroit::SimRollouts sim;
  adroit::StateLayout layout;
  std::string dir, library_path;
  adroit::PolicyLibrary library;
};

// Every entry of column c's label equals local policy p's mean action at step t.
void expectLabel(const adroit::NetworkDataset& data, Eigen::Index c, int p, int t) {
  for (Eigen::Index i = 0; i < data.actions.rows(); ++i)
    ASSERT_NEAR(data.actions(i, c), localAction(p, t, static_cast<int>(i)), 1e-6)
        << "sample " << c << " entry " << i << " (policy " << p << ", step " << t << ")";
}

adroit::DistillationSettings tinySettings() {
  adroit::DistillationSettings s;
  s.spec.hidden_layers = 2;
  s.spec.units = 16;
  s.rollouts_per_policy = 10;
  s.training.epochs = 150;
  s.training.batch_size = 32;
  s.training.learning_rate = 3e-3;
  s.training.held_out_fraction = 0.2;
  s.training.threads = 1;
  s.training.seed = 3;
  s.seed = 5;
  return s;
}

}  // namespace

TEST(NetworkDistillation, CollectsEveryVisitedStateLabelledWithTheMeanAction) {
  Fixture f("collect");
  ASSERT_EQ(adroit::libraryProblem(f.library, f.task, f.layout, f.sim), "");
  const int per_policy = 3;
  adroit::CollectionStats stats;
  const adroit::NetworkDataset data =
      adroit::collectLocalPolicyData(f.sim, f.task, f.layout, f.library, per_policy, f.input(), 7, &stats);
  ASSERT_EQ(stats.failed, 0) << stats.first_failure;
  EXPECT_EQ(stats.rollouts, 2 * per_policy);
  EXPECT_EQ(stats.samples, 2 * per_policy * kT);
  ASSERT_EQ(data.inputs.cols(), 2 * per_policy * kT);
  EXPECT_EQ(data.inputs.rows(), f.input().size());
  EXPECT_EQ(data.actions.rows(), f.layout.nu());
  ASSERT_EQ(data.group.size(), static_cast<std::size_t>(data.inputs.cols()));
  EXPECT_EQ(stats.yaws, (std::vector<double>{0, 0, 0, 10, 10, 10}));
  EXPECT_EQ(stats.labelled_by, (std::vector<int>{0, 0, 0, 1, 1, 1}));
  // Rollout by rollout, T samples each; group = rollout index. The labels are the means
  // although the controllers explored (covariance 0.01 I): they are not the executed commands.
  for (Eigen::Index c = 0; c < data.inputs.cols(); ++c) {
    const int rollout = static_cast<int>(c / kT), t = static_cast<int>(c % kT);
    EXPECT_EQ(data.group[c], rollout);
    expectLabel(data, c, rollout / per_policy, t);
  }
  EXPECT_TRUE(data.inputs.allFinite());
  // The exploration noise made the rollouts of one policy differ (pressures at the last step).
  EXPECT_NE(data.inputs.col(kT - 1), data.inputs.col(2 * kT - 1));
  // Deterministic for a seed.
  const adroit::NetworkDataset again =
      adroit::collectLocalPolicyData(f.sim, f.task, f.layout, f.library, per_policy, f.input(), 7);
  EXPECT_EQ(again.inputs, data.inputs);
  // The no-touch input reads fewer entries, with the same labels.
  const adroit::NetworkDataset partial = adroit::collectLocalPolicyData(
      f.sim, f.task, f.layout, f.library, 1, f.input(adroit::ObservationSet::no_touch), 7);
  EXPECT_LT(partial.inputs.rows(), data.inputs.rows());
  EXPECT_EQ(partial.inputs.cols(), 2 * kT);
}

TEST(NetworkDistillation, TinyNetworkBeatsTheMeanPredictorAndDaggerAddsNetworkRollouts) {
  Fixture f("distill");
  adroit::DistillationSettings settings = tinySettings();
  settings.dagger_rounds = 1;
  settings.dagger_rollouts = 4;
  adroit::DistillationReport report;
  int collected = 0, epochs = 0, trained = 0;
  const adroit::NetworkPolicy policy = adroit::distillLibrary(
      f.sim, f.task, f.layout, f.library, settings, &report, [&](const adroit::DistillationProgress& p) {
        ASSERT_NE(p.summary, nullptr);
        if (p.stage == adroit::DistillationProgress::Stage::collected) ++collected;
        if (p.stage == adroit::DistillationProgress::Stage::epoch) ++epochs;
        if (p.stage == adroit::DistillationProgress::Stage::trained) ++trained;
      });
  EXPECT_EQ(collected, 2);
  EXPECT_EQ(trained, 2);
  EXPECT_EQ(epochs, 2 * settings.training.epochs);
  ASSERT_EQ(report.rounds.size(), 2u);
  const adroit::DistillationRound& cloning = report.rounds[0];
  ASSERT_EQ(cloning.collection.failed, 0) << cloning.collection.first_failure;
  EXPECT_EQ(cloning.dataset_samples, 2 * settings.rollouts_per_policy * kT);
  EXPECT_EQ(cloning.training.held_out_samples % kT, 0);  // whole rollouts
  EXPECT_GT(cloning.training.held_out_samples, 0);
  EXPECT_LT(cloning.heldOutLoss(), 0.5 * cloning.training.mean_predictor_held_out_loss)
      << "held-out " << cloning.heldOutLoss() << ", mean predictor " << cloning.training.mean_predictor_held_out_loss;
  const adroit::DistillationRound& dagger = report.rounds[1];
  EXPECT_EQ(dagger.collection.rollouts, 4);
  EXPECT_EQ(dagger.dataset_samples, cloning.dataset_samples + dagger.collection.samples);
  EXPECT_EQ(dagger.collection.samples, (4 - dagger.collection.failed) * kT);
  EXPECT_LT(dagger.heldOutLoss(), dagger.training.mean_predictor_held_out_loss);
  std::printf("cloning: held-out %.4f (mean predictor %.4f); after DAgger: %.4f (%.4f); %.2f s\n",
              cloning.heldOutLoss(), cloning.training.mean_predictor_held_out_loss, dagger.heldOutLoss(),
              dagger.training.mean_predictor_held_out_loss, report.seconds);
  // The network is for this task on this robot and reads the touch sensors.
  EXPECT_EQ(policy.mismatch(f.sim.jointNames(), f.sim.cylinderNames(), f.sim.touchNames(), f.layout), "");
  EXPECT_EQ(policy.metadata().task, "pickup");
  const std::string csv = adroit::distillationLossCsv(report);
  EXPECT_EQ(csv.rfind("round,epoch,samples,train_loss,held_out_loss,mean_predictor_loss\n0,1,100,", 0), 0u) << csv;
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 1 + 2 * settings.training.epochs);
}

TEST(NetworkDistillation, DaggerLabelsTheNetworksStatesByTheNearestLocalPolicy) {
  Fixture f("dagger");
  adroit::DistillationSettings settings = tinySettings();
  settings.rollouts_per_policy = 2;
  settings.training.epochs = 3;
  const adroit::NetworkPolicy network = adroit::distillLibrary(f.sim, f.task, f.layout, f.library, settings);
  adroit::NetworkDataset data =
      adroit::collectLocalPolicyData(f.sim, f.task, f.layout, f.library, 2, network.input(), 1);
  const Eigen::Index before = data.inputs.cols();
  const int steps = kT + 3;  // longer than the local policies: their last step labels the rest
  adroit::CollectionStats stats;
  const int added =
      adroit::aggregateOnPolicyData(f.sim, f.task, f.layout, f.library, network, data, 5, 11, steps, &stats);
  ASSERT_EQ(stats.rollouts, 5);
  EXPECT_EQ(added, (5 - stats.failed) * steps);
  EXPECT_GT(added, 0) << stats.first_failure;
  ASSERT_EQ(data.inputs.cols(), before + added);
  ASSERT_EQ(data.group.size(), static_cast<std::size_t>(data.inputs.cols()));
  // The library's yaws first, then random ones in [0, 180), each labelled by its nearest policy.
  ASSERT_EQ(stats.yaws.size(), 5u);
  EXPECT_EQ(stats.yaws[0], 0.0);
  EXPECT_EQ(stats.yaws[1], 10.0);
  for (std::size_t i = 0; i < 5; ++i) {
    EXPECT_GE(stats.yaws[i], 0.0);
    EXPECT_LT(stats.yaws[i], 180.0);
    EXPECT_EQ(stats.labelled_by[i], adroit::nearestPolicyIndex({0.0, 10.0}, stats.yaws[i]));
  }
  EXPECT_NE(stats.yaws[2], stats.yaws[3]);
  // New group ids above the old ones, one per successful rollout; labels = k of the nearest
  // policy at min(t, T - 1).
  const int old_max = *std::max_element(data.group.begin(), data.group.begin() + before);
  Eigen::Index c = before;
  std::set<int> groups;
  for (std::size_t i = 0; i < 5; ++i) {
    if (stats.groups[i] < 0) continue;
    EXPECT_GT(stats.groups[i], old_max);
    groups.insert(stats.groups[i]);
    for (int t = 0; t < steps; ++t, ++c) {
      EXPECT_EQ(data.group[c], stats.groups[i]);
      expectLabel(data, c, stats.labelled_by[i], std::min(t, kT - 1));
    }
  }
  EXPECT_EQ(groups.size(), static_cast<std::size_t>(5 - stats.failed));
  EXPECT_EQ(c, data.inputs.cols());
}

TEST(NetworkDistillation, RefusesWhatDoesNotFit) {
  Fixture f("refuse");
  adroit::PolicyLibrary other = f.library;
  other.task = "pickup_from_scratch";
  EXPECT_EQ(adroit::libraryProblem(other, f.task, f.layout, f.sim), "the library is of task 'pickup_from_scratch', not 'pickup'");
  adroit::TrainingTask slower = f.task;
  slower.control_dt = 0.05;
  EXPECT_NE(adroit::libraryProblem(f.library, slower, f.layout, f.sim).find("control_dt 0.04"), std::string::npos);
  EXPECT_THROW(adroit::collectLocalPolicyData(f.sim, f.task, f.layout, other, 1, f.input(), 1), std::invalid_argument);
  EXPECT_THROW(adroit::collectLocalPolicyData(f.sim, f.task, f.layout, f.library, 0, f.input(), 1),
               std::invalid_argument);
  adroit::DistillationSettings s;
  EXPECT_EQ(s.validate(), "");
  s.rollouts_per_policy = 0;
  EXPECT_NE(s.validate().find("rollouts_per_policy"), std::string::npos);
  s = adroit::DistillationSettings{};
  s.spec.hidden_layers = 0;
  EXPECT_NE(s.validate(), "");
  s = adroit::DistillationSettings{};
  s.dagger_rounds = 2;
  s.dagger_rollouts = 0;
  EXPECT_NE(s.validate().find("dagger_rollouts"), std::string::npos);
  // Cancelled before the rollouts: nothing is kept.
  std::atomic<bool> cancel{true};
  EXPECT_THROW(adroit::collectLocalPolicyData(f.sim, f.task, f.layout, f.library, 1, f.input(), 1, nullptr, &cancel),
               adroit::DistillationCancelled);
}

namespace {

struct ToolRun {
  int status;
  std::string output;  // stdout and stderr
};

ToolRun runTool(std::vector<std::string> args) {
  args.insert(args.begin(), TRAIN_NETWORK_POLICY_BINARY);
  adroit::ProgramOptions options;
  options.timeout_s = 120.0;
  options.capture_output = true;
  options.merge_stderr = true;
  const adroit::ProgramResult r = adroit::runProgram(args, options);
  return {r.exit_code, r.output + (r.ok() || r.exit_code > 0 ? "" : " [" + r.describe() + "]")};
}

}  // namespace

TEST(TrainNetworkPolicyTool, TrainsATinyNetworkAndRefusesBadInputInOneLine) {
  Fixture f("tool");
  const std::string out = f.dir + "/net.policy";
  const std::vector<std::string> common = {"--library", f.library_path, "--task", "pickup", "--tasks-dir", TASK_DIR,
                                           "--description-dir", ADROIT_DESCRIPTION_DIR, "--out", out};
  const auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> a = common;
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
  };
  struct Case {
    std::vector<std::string> args;
    std::string says;
  };
  // A library of another task: the same policies under pickup_from_scratch.
  adroit::PolicyLibrary foreign;
  foreign.task = "pickup_from_scratch";
  foreign.scene = "tube";
  foreign.entries = {{0.0, f.dir + "/yaw000.tvlg", nullptr, ""}};
  adroit::writePolicyLibrary(f.dir + "/foreign.library", foreign);
  std::ofstream(f.dir + "/garbage.library") << "not a library\n";
  const std::vector<Case> bad = {
      {with({"--observation", "camera"}), "--observation"},
      {with({"--layers", "0"}), "--layers must be in [1, 64], got 0"},
      {with({"--units", "5000"}), "--units must be in [1, 4096], got 5000"},
      {{"--library", f.dir + "/garbage.library", "--tasks-dir", TASK_DIR, "--out", out}, "garbage.library"},
      {{"--library", f.dir + "/foreign.library", "--tasks-dir", TASK_DIR, "--out", out}, "pickup_from_scratch"},
      {with({"--task", "no_such_task"}), "no_such_task"},
      {{"--library", f.library_path, "--tasks-dir", TASK_DIR, "--out", f.dir + "/missing/net.policy"},
       "does not exist"},
  };
  for (const Case& c : bad) {
    const ToolRun r = runTool(c.args);
    EXPECT_EQ(r.status, 2) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
    EXPECT_EQ(r.output.rfind("train_network_policy: ", 0), 0u) << r.output;
    EXPECT_NE(r.output.find(c.says), std::string::npos) << r.output;
    EXPECT_FALSE(std::filesystem::exists(out));
  }
  // A tiny end-to-end run: 2 policies x 3 rollouts of 5 steps, 2 x 16 network, one DAgger round.
  const ToolRun r = runTool(with({"--layers", "2", "--units", "16", "--rollouts", "3", "--epochs", "20", "--batch",
                                  "16", "--dagger", "1", "--dagger-rollouts", "3", "--dagger-steps", "5",
                                  "--held-out", "0.34", "--workers", "2", "--seed", "4"}));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("RESULT adroit_learning/network_heldout_loss/full_2x16 "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("round 1 epoch    20/20"), std::string::npos) << r.output;
  const adroit::NetworkPolicy read = adroit::readNetworkPolicyFile(out);
  EXPECT_EQ(read.spec().hidden_layers, 2);
  EXPECT_EQ(read.spec().units, 16);
  std::ifstream csv(out + ".loss.csv");
  std::string header;
  std::getline(csv, header);
  EXPECT_EQ(header, "round,epoch,samples,train_loss,held_out_loss,mean_predictor_loss");
}
