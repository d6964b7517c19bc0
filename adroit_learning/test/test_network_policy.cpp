// Network policies (thesis 11.6): the inputs each observation set reads, training that beats
// the mean predictor on held-out rollouts, files that read back to the same actions, and the
// refusals (damaged files, another robot, bad training data) as one clear line each.
#include <adroit_learning/network_policy.h>
#include <adroit_learning/network_training.h>
#include <adroit_learning/policy_file.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <random>
#include <sstream>

namespace {

using adroit::NetworkPolicy;
using adroit::NetworkPolicyMetadata;
using adroit::ObservationSet;

const std::vector<std::string> kJoints = {"J0", "J1", "J2"};
const std::vector<std::string> kCylinders = {"C_a", "C_b", "C_c", "C_d"};
const std::vector<std::string> kTouch = {"T0", "T1"};

// 3 joints, 4 cylinders of which C_d is locked (nu = 3); with the object: nx = 22, else 10.
adroit::StateLayout makeLayout(bool object) {
  adroit::TrainingTask task;
  task.name = "test_task";
  task.scene = object ? "tube" : "hand";
  task.locked_cylinders = {"C_d"};
  if (object) task.object_position_weight = 1;
  return adroit::StateLayout(task, kJoints, kCylinders, object);
}

NetworkPolicyMetadata metadataFor(const adroit::StateLayout& layout, ObservationSet set) {
  return NetworkPolicyMetadata::forLayout(layout, kTouch, set, "test_task", "hand", 0.04);
}

adroit::NetworkSpec smallSpec() {
  adroit::NetworkSpec spec;
  spec.hidden_layers = 2;
  spec.units = 16;
  return spec;
}

Eigen::VectorXd actionOf(NetworkPolicy& policy, const Eigen::VectorXd& x, const Eigen::VectorXd& touch) {
  Eigen::VectorXd u(policy.nu());
  policy.action(0, x, touch, u);
  return u;
}

std::string tempPath(const std::string& name) { return std::string(::testing::TempDir()) + "/" + name; }

std::string fileText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

void writeText(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::trunc);
  out << text;
}

std::string readError(const std::string& path) {
  try {
    adroit::readNetworkPolicyFile(path);
  } catch (const adroit::PolicyFileError& e) {
    return e.what();
  }
  return "";
}

// A network whose normalisation is not the identity, so files must carry it.
NetworkPolicy examplePolicy(ObservationSet set, bool object) {
  NetworkPolicy policy(metadataFor(makeLayout(object), set), smallSpec());
  adroit::NetworkNormalisation n;
  n.input_mean = Eigen::VectorXf::LinSpaced(policy.inputSize(), -1.0f, 2.0f);
  n.input_std = Eigen::VectorXf::LinSpaced(policy.inputSize(), 0.5f, 3.0f);
  n.action_mean = Eigen::VectorXf::Constant(policy.nu(), 0.25f);
  n.action_std = Eigen::VectorXf::Constant(policy.nu(), 1.5f);
  policy.setNormalisation(n);
  return policy;
}

// Samples of a smooth nonlinear map from the inputs to three actions, in rollouts of 50
// neighbouring states (a slow random walk), so whole rollouts can be held out.
adroit::NetworkDataset syntheticDataset(int inputs, int rollouts, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> start(-1.5f, 1.5f);
  std::normal_distribution<float> step(0.0f, 0.15f);
  const int per_rollout = 50, n = rollouts * per_rollout;
  adroit::NetworkDataset data;
  data.inputs.resize(inputs, n);
  data.actions.resize(3, n);
  for (int r = 0; r < rollouts; ++r) {
    Eigen::VectorXf x(inputs);
    for (int i = 0; i < inputs; ++i) x[i] = start(rng);
    for (int s = 0; s < per_rollout; ++s) {
      for (int i = 0; i < inputs; ++i) x[i] = std::clamp(x[i] + step(rng), -1.5f, 1.5f);
      const int c = r * per_rollout + s;
      // Inputs on different scales and offsets: the normalisation has to work.
      data.inputs.col(c) = x.array() * Eigen::ArrayXf::LinSpaced(inputs, 0.2f, 5.0f) + 3.0f;
      data.actions(0, c) = 2.0f * std::sin(x[0] + 0.5f * x[1]);
      data.actions(1, c) = std::tanh(2.0f * x[2] - x[3]) + 0.5f * x[inputs - 1];
      data.actions(2, c) = x[4] * x[5] + 0.3f * std::cos(2.0f * x[6]) - 1.0f;
      data.group.push_back(r);
    }
  }
  return data;
}

}  // namespace

TEST(ObservationSet, NamesRoundTripAndUnknownOnesListTheValid) {
  for (ObservationSet set : {ObservationSet::full, ObservationSet::partial, ObservationSet::no_touch})
    EXPECT_EQ(adroit::observationSetFromName(adroit::name(set)), set);
  try {
    adroit::observationSetFromName("partial_touch");
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_EQ(std::string(e.what()), "unknown observation set 'partial_touch' (valid: full, partial, no_touch)");
  }
}

TEST(NetworkInput, EachSetReadsItsEntriesInOrder) {
  const adroit::StateLayout layout = makeLayout(true);
  ASSERT_EQ(layout.nx(), 22);
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(22, 0, 21);  // entry i holds i
  const Eigen::VectorXd touch = (Eigen::VectorXd(2) << 100, 101).finished();
  const auto read = [&](ObservationSet set) {
    const adroit::NetworkInput input(set, layout, 2);
    std::vector<float> out(static_cast<std::size_t>(input.size()));
    input.fill(x, touch, out.data());
    return out;
  };
  // The object's entries by the layout's own accessors: position, rotation, both velocities.
  std::vector<float> without_object;
  const int velocity = layout.qdot() + layout.joints();
  for (int i = 0; i < 22; ++i) {
    const bool pose = i >= layout.objectPosition() && i < layout.objectPosition() + 6;
    const bool motion = i >= velocity && i < velocity + 6;
    if (!pose && !motion) without_object.push_back(static_cast<float>(i));
  }
  std::vector<float> full(x.data(), x.data() + 22), partial = without_object;
  full.insert(full.end(), {100, 101});
  partial.insert(partial.end(), {100, 101});
  EXPECT_EQ(read(ObservationSet::full), full);
  EXPECT_EQ(read(ObservationSet::partial), partial);
  EXPECT_EQ(read(ObservationSet::no_touch), without_object);
  // Without an object, partial is full.
  const adroit::NetworkInput plain(ObservationSet::partial, makeLayout(false), 2);
  EXPECT_EQ(plain.size(), 12);
  EXPECT_EQ(adroit::NetworkInput(ObservationSet::full, makeLayout(false), 2).size(), 12);
}

TEST(NetworkInput, WrongSizesAndBadLayoutsAreRefused) {
  const adroit::NetworkInput input(ObservationSet::full, makeLayout(false), 2);
  std::vector<float> out(12);
  EXPECT_THROW(input.fill(Eigen::VectorXd::Zero(9), Eigen::VectorXd::Zero(2), out.data()), std::invalid_argument);
  EXPECT_THROW(input.fill(Eigen::VectorXd::Zero(10), Eigen::VectorXd::Zero(3), out.data()), std::invalid_argument);
  EXPECT_THROW(adroit::NetworkInput(ObservationSet::full, "q:3 qdot", 0), std::invalid_argument);
  EXPECT_THROW(adroit::NetworkInput(ObservationSet::full, "q:-3", 0), std::invalid_argument);
  EXPECT_THROW(adroit::NetworkInput(ObservationSet::full, "", 0), std::invalid_argument);
}

TEST(NetworkPolicy, PartialObservationNeverReadsTheObjectButFullDoes) {
  const adroit::StateLayout layout = makeLayout(true);
  NetworkPolicy partial(metadataFor(layout, ObservationSet::partial), smallSpec());
  NetworkPolicy full(metadataFor(layout, ObservationSet::full), smallSpec());
  std::mt19937_64 rng(3);
  std::normal_distribution<double> normal;
  Eigen::VectorXd x(layout.nx()), touch(2);
  for (int i = 0; i < x.size(); ++i) x[i] = normal(rng);
  touch << 0.3, -0.7;
  Eigen::VectorXd moved = x;  // other object pose and velocity, the same hand
  moved.segment(layout.objectPosition(), 6).array() += 0.8;
  moved.segment(layout.qdot() + layout.joints(), 6).array() -= 1.1;
  EXPECT_EQ(actionOf(partial, x, touch), actionOf(partial, moved, touch));
  EXPECT_NE(actionOf(full, x, touch), actionOf(full, moved, touch));
  // NaN in the object entries cannot reach a partial network's action either.
  moved.segment(layout.objectPosition(), 3).setConstant(std::nan(""));
  EXPECT_EQ(actionOf(partial, x, touch), actionOf(partial, moved, touch));
}

TEST(NetworkPolicy, NoTouchIgnoresTouchWhileTheOthersReadIt) {
  const adroit::StateLayout layout = makeLayout(false);
  NetworkPolicy no_touch(metadataFor(layout, ObservationSet::no_touch), smallSpec());
  NetworkPolicy partial(metadataFor(layout, ObservationSet::partial), smallSpec());
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(layout.nx(), -1, 1);
  const Eigen::VectorXd a = (Eigen::VectorXd(2) << 0, 0).finished(), b = (Eigen::VectorXd(2) << 3, -2).finished();
  EXPECT_EQ(actionOf(no_touch, x, a), actionOf(no_touch, x, b));
  EXPECT_EQ(actionOf(no_touch, x, a), actionOf(no_touch, x, Eigen::VectorXd()));  // not even its size
  EXPECT_NE(actionOf(partial, x, a), actionOf(partial, x, b));
}

TEST(NetworkPolicy, ActionsAreClampedAndWrongSizesRefused) {
  NetworkPolicy policy = examplePolicy(ObservationSet::full, false);
  EXPECT_EQ(policy.kind(), "network");
  EXPECT_EQ(policy.horizon(), 0);
  adroit::NetworkNormalisation n = policy.normalisation();
  n.action_mean.setConstant(40.0f);  // every action far beyond the valve range
  policy.setNormalisation(n);
  const Eigen::VectorXd u = actionOf(policy, Eigen::VectorXd::Zero(10), Eigen::VectorXd::Zero(2));
  EXPECT_EQ(u, Eigen::VectorXd::Constant(3, 5.0));
  Eigen::VectorXd wrong(2);
  EXPECT_THROW(policy.action(0, Eigen::VectorXd::Zero(10), Eigen::VectorXd::Zero(2), wrong), std::invalid_argument);
  EXPECT_THROW(actionOf(policy, Eigen::VectorXd::Zero(11), Eigen::VectorXd::Zero(2)), std::invalid_argument);
  EXPECT_THROW(actionOf(policy, Eigen::VectorXd::Zero(10), Eigen::VectorXd::Zero(1)), std::invalid_argument);
  n.input_std[0] = std::nanf("");
  EXPECT_THROW(policy.setNormalisation(n), std::invalid_argument);
  EXPECT_THROW(policy.setLayer(0, Eigen::MatrixXf::Zero(3, 3), Eigen::VectorXf::Zero(3)), std::invalid_argument);
}

TEST(NetworkPolicy, CopiesAreIndependent) {
  NetworkPolicy a = examplePolicy(ObservationSet::full, false);
  NetworkPolicy b = a;
  const Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(10, -1, 1), touch = Eigen::VectorXd::Ones(2);
  const Eigen::VectorXd before = actionOf(a, x, touch);
  EXPECT_EQ(actionOf(b, x, touch), before);
  b.setLayer(0, Eigen::MatrixXf::Zero(16, 12), Eigen::VectorXf::Zero(16));
  EXPECT_EQ(actionOf(a, x, touch), before);
  EXPECT_NE(actionOf(b, x, touch), before);
}

TEST(NetworkPolicy, MismatchNamesWhatDiffersFromTheRobot) {
  const adroit::StateLayout plain = makeLayout(false), with_object = makeLayout(true);
  const NetworkPolicy partial(metadataFor(plain, ObservationSet::partial), smallSpec());
  EXPECT_EQ(partial.mismatch(kJoints, kCylinders, kTouch, plain), "");
  const std::string touch = partial.mismatch(kJoints, kCylinders, {"T0", "T9"}, plain);
  EXPECT_NE(touch.find("touch sensors differ"), std::string::npos) << touch;
  EXPECT_NE(partial.mismatch(kJoints, kCylinders, {}, plain), "");  // a robot without touch sensors
  const std::string joints = partial.mismatch({"J0", "J1", "JX"}, kCylinders, kTouch, plain);
  EXPECT_NE(joints.find("joints differ"), std::string::npos) << joints;
  EXPECT_NE(partial.mismatch(kJoints, {"C_a", "C_b", "C_c"}, kTouch, plain).find("cylinders"), std::string::npos);
  // Another state layout: the network was trained on the object task's state.
  const NetworkPolicy full(metadataFor(with_object, ObservationSet::full), smallSpec());
  const std::string layout = full.mismatch(kJoints, kCylinders, kTouch, plain);
  EXPECT_NE(layout.find("state layout"), std::string::npos) << layout;
  EXPECT_EQ(layout.find('\n'), std::string::npos);
  // A network that does not read touch runs on a robot without touch sensors.
  const NetworkPolicy no_touch(metadataFor(plain, ObservationSet::no_touch), smallSpec());
  EXPECT_EQ(no_touch.mismatch(kJoints, kCylinders, {}, plain), "");
}

TEST(NetworkPolicyFile, RoundTripGivesIdenticalActions) {
  for (const ObservationSet set : {ObservationSet::full, ObservationSet::partial, ObservationSet::no_touch}) {
    NetworkPolicy policy = examplePolicy(set, true);
    const std::string path = tempPath("round_trip_" + adroit::name(set) + ".net");
    adroit::writeNetworkPolicyFile(path, policy);
    NetworkPolicy read = adroit::readNetworkPolicyFile(path);
    EXPECT_EQ(read.metadata().task, "test_task");
    EXPECT_EQ(read.metadata().scene, "hand");
    EXPECT_DOUBLE_EQ(read.metadata().control_dt, 0.04);
    EXPECT_EQ(read.metadata().observation, set);
    EXPECT_EQ(read.metadata().joints, kJoints);
    EXPECT_EQ(read.metadata().cylinders, kCylinders);
    EXPECT_EQ(read.metadata().touch, kTouch);
    EXPECT_EQ(read.metadata().actions, (std::vector<std::string>{"C_a", "C_b", "C_c"}));
    EXPECT_EQ(read.metadata().state_layout, makeLayout(true).describe());
    EXPECT_EQ(read.spec().hidden_layers, 2);
    EXPECT_EQ(read.spec().units, 16);
    std::mt19937_64 rng(5);
    std::normal_distribution<double> normal(0.0, 2.0);
    for (int trial = 0; trial < 100; ++trial) {
      Eigen::VectorXd x(22), touch(2);
      for (int i = 0; i < 22; ++i) x[i] = normal(rng);
      touch << normal(rng), normal(rng);
      ASSERT_EQ(actionOf(read, x, touch), actionOf(policy, x, touch)) << adroit::name(set) << " trial " << trial;
    }
    const std::string first_line = fileText(path).substr(0, fileText(path).find('\n'));
    EXPECT_EQ(first_line, "adroit_network_policy 1");
  }
}

TEST(NetworkPolicyFile, DamagedAndForeignFilesAreRefusedNamingTheProblem) {
  const std::string good = tempPath("good.net"), path = tempPath("damaged.net");
  adroit::writeNetworkPolicyFile(good, examplePolicy(ObservationSet::partial, true));
  const std::string text = fileText(good);
  const auto refusal = [&](const std::string& damaged) {
    writeText(path, damaged);
    return readError(path);
  };
  const auto replaced = [&](const std::string& from, const std::string& to) {
    std::string t = text;
    const auto at = t.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    return t.replace(at, from.size(), to);
  };
  // The first number of block weight.1 made non-finite, or too large for a float.
  const std::size_t weight1 = text.find("\n", text.find("weight.1 ")) + 1;
  const std::string number = text.substr(weight1, text.find_first_of(" \n", weight1) - weight1);
  const auto withFirstWeight = [&](const std::string& value) {
    return std::string(text).replace(weight1, number.size(), value);
  };
  std::string e = refusal(withFirstWeight("nan"));
  EXPECT_EQ(e.rfind(path + ":", 0), 0u) << e;
  EXPECT_NE(e.find("weight.1"), std::string::npos) << e;
  EXPECT_NE(e.find("not finite"), std::string::npos) << e;
  e = refusal(withFirstWeight("1e300"));
  EXPECT_NE(e.find("range of a float"), std::string::npos) << e;
  // Cut inside a block: the message gives the file's own line number of that block.
  const std::string cut = text.substr(0, text.size() * 6 / 10);
  e = refusal(cut);
  EXPECT_EQ(e.rfind(path + ":", 0), 0u) << e;
  EXPECT_NE(e.find("the file ends after"), std::string::npos) << e;
  int line = 0, block_line = 0;
  std::istringstream lines(cut);
  for (std::string l; std::getline(lines, l);)
    if (++line, l.rfind("weight.", 0) == 0 || l.rfind("bias.", 0) == 0) block_line = line;
  EXPECT_EQ(e.rfind(path + ":" + std::to_string(block_line) + ": block", 0), 0u) << e << " (expected line " << block_line << ")";
  e = refusal(text.substr(0, text.find("matrices")));
  EXPECT_EQ(e, path + ": truncated: no 'matrices' line after the header");
  e = refusal(replaced("adroit_network_policy 1", "adroit_tvlg_policy 1"));
  EXPECT_NE(e.find("not an adroit network policy"), std::string::npos) << e;
  e = refusal(replaced("adroit_network_policy 1", "adroit_network_policy 2"));
  EXPECT_EQ(e, path + ": format version 2, this build reads version 1");
  e = refusal(replaced("observation partial", "observation everything"));
  EXPECT_NE(e.find("unknown observation set 'everything'"), std::string::npos) << e;
  // Header sizes the blocks do not hold: checked against every block before allocating.
  e = refusal(replaced("units 16", "units 17"));
  EXPECT_NE(e.find("block 'weight.0': is 16x"), std::string::npos) << e;
  e = refusal(replaced("hidden_layers 2", "hidden_layers 64"));
  EXPECT_NE(e.find("blocks, a network of 64 hidden layers has"), std::string::npos) << e;
  e = refusal(replaced("hidden_layers 2", "hidden_layers 100000000000"));
  EXPECT_NE(e.find("'hidden_layers' must be a whole number in [1, 64]"), std::string::npos) << e;
  e = refusal(replaced("inputs 12", "inputs 13"));
  EXPECT_NE(e.find("header says 13 inputs"), std::string::npos) << e;
  e = refusal(replaced("input_std 12 1\n", "input_std 12 1\n-"));
  EXPECT_NE(e.find("not positive"), std::string::npos) << e;
  e = refusal(replaced("touch T0 T1\n", ""));
  EXPECT_EQ(e, path + ": header field 'touch' missing");
  e = refusal("");
  EXPECT_EQ(e, path + ": empty file");
  EXPECT_EQ(readError(tempPath("missing.net")).rfind(tempPath("missing.net") + ":", 0), 0u);
  EXPECT_EQ(readError(good), "");
}

TEST(NetworkPolicyFile, FifoIsRefusedWithoutBlocking) {
  const std::string fifo = tempPath("policy_fifo.net");
  ::unlink(fifo.c_str());
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const auto start = std::chrono::steady_clock::now();
  const std::string e = readError(fifo);  // no writer: a plain open would block for good
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 0.5);
  EXPECT_EQ(e, fifo + ": not a regular file (a FIFO)");
  ::unlink(fifo.c_str());
}

TEST(NetworkTraining, BeatsTheMeanPredictorOnHeldOutRollouts) {
  const adroit::StateLayout layout = makeLayout(false);
  const NetworkPolicyMetadata metadata = metadataFor(layout, ObservationSet::full);
  const adroit::NetworkDataset data = syntheticDataset(12, 60, 7);  // 3000 samples
  adroit::NetworkSpec spec;
  spec.hidden_layers = 2;
  spec.units = 64;
  adroit::NetworkTrainingSettings settings;
  settings.epochs = 20;
  settings.batch_size = 64;
  settings.threads = 1;  // small batches: threads would cost more than they save
  settings.learning_rate = 3e-3;
  settings.held_out_fraction = 0.2;
  settings.seed = 11;
  adroit::NetworkTrainingReport report;
  int calls = 0;
  NetworkPolicy policy = adroit::trainNetworkPolicy(data, spec, settings, metadata, &report,
                                                    [&](int epoch, double, double) { EXPECT_EQ(epoch, ++calls); });
  EXPECT_EQ(calls, 20);
  ASSERT_EQ(report.train_loss.size(), 20u);
  ASSERT_EQ(report.held_out_loss.size(), 20u);
  EXPECT_EQ(report.held_out_samples, 600);  // 12 whole rollouts of 50
  EXPECT_EQ(report.train_samples + report.held_out_samples, 3000);
  EXPECT_GT(report.mean_predictor_held_out_loss, 0.5);
  EXPECT_LT(report.held_out_loss.back(), 0.3 * report.mean_predictor_held_out_loss)
      << "held-out " << report.held_out_loss.back() << ", mean predictor " << report.mean_predictor_held_out_loss;
  EXPECT_LT(report.train_loss.back(), report.train_loss.front());
  std::printf("held-out loss %.4f (train %.4f), mean predictor %.4f, %.2f s\n", report.held_out_loss.back(),
              report.train_loss.back(), report.mean_predictor_held_out_loss, report.seconds);
  const std::string csv = adroit::networkLossCsv(report);
  EXPECT_EQ(csv.rfind("epoch,train_loss,held_out_loss,mean_predictor_loss\n1,", 0), 0u);
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 21);
  // action() (the control loop's allocation-free path) agrees with predict() (the module's
  // batch forward, which training optimised) up to float rounding.
  const Eigen::MatrixXf predicted = policy.predict(data.inputs.leftCols(20));
  for (int c = 0; c < 20; ++c) {
    // The network input is [x | touch]: split the column back.
    const Eigen::VectorXd column = data.inputs.col(c).cast<double>();
    const Eigen::VectorXd u = actionOf(policy, column.head(10), column.tail(2));
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(u[k], std::clamp<double>(predicted(k, c), -5, 5), 1e-4 * (1 + std::abs(predicted(k, c))));
  }
}

TEST(NetworkTraining, IsDeterministicForASeed) {
  const NetworkPolicyMetadata metadata = metadataFor(makeLayout(false), ObservationSet::full);
  const adroit::NetworkDataset data = syntheticDataset(12, 10, 2);
  adroit::NetworkTrainingSettings settings;
  settings.epochs = 3;
  settings.threads = 1;
  const NetworkPolicy a = adroit::trainNetworkPolicy(data, smallSpec(), settings, metadata, nullptr);
  const NetworkPolicy b = adroit::trainNetworkPolicy(data, smallSpec(), settings, metadata, nullptr);
  settings.seed = 2;
  const NetworkPolicy c = adroit::trainNetworkPolicy(data, smallSpec(), settings, metadata, nullptr);
  for (int l = 0; l < a.layerCount(); ++l) {
    EXPECT_EQ(a.weight(l), b.weight(l));
    EXPECT_EQ(a.bias(l), b.bias(l));
  }
  EXPECT_NE(a.weight(0), c.weight(0));
}

TEST(NetworkTraining, BadDataAndSettingsAreRefusedInOneLine) {
  const NetworkPolicyMetadata metadata = metadataFor(makeLayout(false), ObservationSet::full);
  const adroit::NetworkDataset good = syntheticDataset(12, 4, 1);
  adroit::NetworkTrainingSettings settings;
  settings.epochs = 1;
  const auto refusal = [&](const adroit::NetworkDataset& data, const adroit::NetworkTrainingSettings& s) {
    try {
      adroit::trainNetworkPolicy(data, smallSpec(), s, metadata, nullptr);
    } catch (const std::invalid_argument& e) {
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
      return std::string(e.what());
    }
    return std::string();
  };
  adroit::NetworkDataset bad = good;
  bad.inputs(3, 17) = std::nanf("");
  EXPECT_EQ(refusal(bad, settings), "network training: input 3 of sample 17 is not finite");
  bad = good;
  bad.actions(1, 5) = std::numeric_limits<float>::infinity();
  EXPECT_EQ(refusal(bad, settings), "network training: action 1 of sample 5 is not finite");
  bad = good;
  bad.inputs.resize(12, 0);
  bad.actions.resize(3, 0);
  bad.group.clear();
  EXPECT_EQ(refusal(bad, settings), "network training: no samples");
  bad = good;
  bad.inputs.conservativeResize(11, Eigen::NoChange);
  EXPECT_NE(refusal(bad, settings).find("the policy needs 12 inputs and 3 actions"), std::string::npos);
  bad = good;
  bad.group.pop_back();
  EXPECT_NE(refusal(bad, settings).find("group ids for 200 samples"), std::string::npos);
  bad = good;
  std::fill(bad.group.begin(), bad.group.end(), 4);
  EXPECT_NE(refusal(bad, settings).find("at least two groups"), std::string::npos);
  adroit::NetworkTrainingSettings s = settings;
  s.epochs = 0;
  EXPECT_EQ(refusal(good, s), "network training: epochs must be in [1, 1000000], got 0");
  s = settings;
  s.learning_rate = std::nan("");
  EXPECT_NE(refusal(good, s).find("learning_rate"), std::string::npos);
  s = settings;
  s.held_out_fraction = 1;
  EXPECT_NE(refusal(good, s).find("held_out_fraction"), std::string::npos);
  adroit::NetworkSpec spec;
  spec.units = 0;
  EXPECT_THROW(adroit::trainNetworkPolicy(good, spec, settings, metadata, nullptr), std::invalid_argument);
  // No held-out set: NaN held-out losses, still trains.
  s = settings;
  s.held_out_fraction = 0;
  adroit::NetworkTrainingReport report;
  adroit::trainNetworkPolicy(good, smallSpec(), s, metadata, &report);
  EXPECT_TRUE(std::isnan(report.held_out_loss.at(0)));
  EXPECT_TRUE(std::isnan(report.mean_predictor_held_out_loss));
  EXPECT_EQ(report.train_samples, 200);
}
