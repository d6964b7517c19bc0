// The pickup evaluation program (tools/pickup_eval.cpp): its pure parts (Wilson interval, yaw
// grid, random yaws, CSV fields, names and --require values), compiled here from the tool's own
// source without its main; and the built binary on the task's scene with trivial policies
// (K = 0, k = 0: the hand holds still, so nothing is expected to succeed): every output file
// written, RESULT and INFO lines, and bad input refused with exit status 2 before anything runs.
#define PICKUP_EVAL_NO_MAIN
#pragma GCC diagnostic ignored "-Wunused-function"  // the tool's steps that only its main calls
#include "../tools/pickup_eval.cpp"

#include <adroit_core/run_program.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iomanip>
#include <set>
#include <sstream>

namespace {

namespace fs = std::filesystem;

// ---- pure parts ----

TEST(PickupEvalHelpers, WilsonIntervalMatchesKnownValues) {
  // Wilson (1927) with z = 1.96: 0/10 -> [0, 0.2775], 5/10 -> [0.2366, 0.7634], 10/10 -> [0.7225, 1].
  Interval i = wilsonInterval(0, 10);
  EXPECT_NEAR(i.low, 0.0, 1e-12);
  EXPECT_NEAR(i.high, 0.2775, 1e-4);
  i = wilsonInterval(5, 10);
  EXPECT_NEAR(i.low, 0.2366, 1e-4);
  EXPECT_NEAR(i.high, 0.7634, 1e-4);
  i = wilsonInterval(10, 10);
  EXPECT_NEAR(i.low, 0.7225, 1e-4);
  EXPECT_NEAR(i.high, 1.0, 1e-12);
  i = wilsonInterval(91, 100);  // 91 %: [83.8, 95.2]
  EXPECT_NEAR(i.low, 0.8378, 1e-4);
  EXPECT_NEAR(i.high, 0.9519, 1e-4);
  i = wilsonInterval(0, 0);
  EXPECT_EQ(i.low, 0.0);
  EXPECT_EQ(i.high, 1.0);
}

TEST(PickupEvalHelpers, YawGridCoversHalfATurnBelow180) {
  const std::vector<double> two = yawGrid(2);
  ASSERT_EQ(two.size(), 90u);
  EXPECT_EQ(two.front(), 0.0);
  EXPECT_EQ(two.back(), 178.0);
  EXPECT_EQ(yawGrid(45), (std::vector<double>{0, 45, 90, 135}));
  EXPECT_EQ(yawGrid(90), (std::vector<double>{0, 90}));
  EXPECT_EQ(yawGrid(7).size(), 26u);  // 0 .. 175
  const std::vector<double> fine = yawGrid(0.1);
  EXPECT_EQ(fine.size(), 1800u);
  EXPECT_LT(fine.back(), 180.0);
}

TEST(PickupEvalHelpers, RandomYawsAreInRangeAndFollowTheSeed) {
  const std::vector<double> a = randomYaws(1000, 1), b = randomYaws(1000, 1), c = randomYaws(1000, 2);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
  double low = 180, high = 0, sum = 0;
  for (double y : a) low = std::min(low, y), high = std::max(high, y), sum += y;
  EXPECT_GE(low, 0.0);
  EXPECT_LT(high, 180.0);
  EXPECT_LT(low, 2.0);
  EXPECT_GT(high, 178.0);
  EXPECT_NEAR(sum / a.size(), 90.0, 5.0);
  EXPECT_EQ(randomYaws(3, 1), std::vector<double>(a.begin(), a.begin() + 3));  // a prefix of the same stream
}

TEST(PickupEvalHelpers, CsvFieldsQuoteOnlyWhatNeedsIt) {
  EXPECT_EQ(csvField("plain"), "plain");
  EXPECT_EQ(csvField("a,b"), "\"a,b\"");
  EXPECT_EQ(csvField("say \"x\""), "\"say \"\"x\"\"\"");
  EXPECT_EQ(csvField("two\nlines"), "\"two\nlines\"");
  EXPECT_EQ(numberField(kNaN), "");
  EXPECT_EQ(numberField(12.5), "12.5");
  // A yaw read back from a simulated state: rounding noise around 0 is 0, -0 is 0.
  EXPECT_EQ(yawList({3.52933e-32, 18, 12.5, -0.0}), "0 18 12.5 0");
}

TEST(PickupEvalHelpers, NamesAssignmentsAndRequirements) {
  EXPECT_TRUE(validName("demo_12.5"));
  EXPECT_TRUE(validName("Policy-NN+touch"));
  EXPECT_FALSE(validName(""));
  EXPECT_FALSE(validName("a b"));
  EXPECT_FALSE(validName("a,b"));
  EXPECT_FALSE(validName("a/b"));
  EXPECT_EQ(splitAssignment("--policy", "nn=/tmp/x=y.txt"), std::make_pair(std::string("nn"), std::string("/tmp/x=y.txt")));
  EXPECT_THROW(splitAssignment("--policy", "nopath"), InputError);
  EXPECT_THROW(splitAssignment("--policy", "=path"), InputError);
  EXPECT_THROW(splitAssignment("--policy", "name="), InputError);
  EXPECT_THROW(splitAssignment("--policy", "bad name=p"), InputError);
  EXPECT_EQ(parseRequirement("nn=80"), std::make_pair(std::string("nn"), 80.0));
  EXPECT_EQ(parseRequirement("nn=72.5%"), std::make_pair(std::string("nn"), 72.5));
  EXPECT_THROW(parseRequirement("nn=101"), InputError);
  EXPECT_THROW(parseRequirement("nn=-1"), InputError);
  EXPECT_THROW(parseRequirement("nn=x"), InputError);
  EXPECT_THROW(parseRequirement("nn=nan"), InputError);
  EXPECT_EQ(demoLabel(30.0), "demo_30");
  EXPECT_EQ(demoLabel(12.46), "demo_12.5");
  EXPECT_EQ(uniqueName("demo_30", {"demo_30", "demo_30_2"}), "demo_30_3");
  EXPECT_EQ(uniqueName("x", {"y"}), "x");
  EXPECT_EQ(conditionLabel(0), "A");
  EXPECT_EQ(conditionLabel(25), "Z");
  EXPECT_EQ(conditionLabel(26), "AA");
  EXPECT_EQ(yawList({0, 12.5, 90}), "0 12.5 90");
}

// The ceiling counts a random trial once when any TVLG policy succeeds there, never a network's
// or a library's success, and is undefined without TVLG policies.
TEST(PickupEvalHelpers, LocalPolicyCeilingIsTheUnionOfTvlgSuccesses) {
  auto policy = [](const std::string& kind, std::vector<bool> outcomes) {
    Evaluated p;
    p.kind = kind;
    for (bool ok : outcomes) p.random.push_back(TrialResult{0.0, ok, kNaN, kNaN, ""});
    return p;
  };
  std::vector<Evaluated> policies;
  EXPECT_TRUE(std::isnan(localPolicyCeiling(policies)));
  policies.push_back(policy("network", {true, true, true, true}));
  policies.push_back(policy("library", {true, true, true, true}));
  EXPECT_TRUE(std::isnan(localPolicyCeiling(policies)));
  policies.push_back(policy("tvlg", {true, false, false, false}));
  EXPECT_DOUBLE_EQ(localPolicyCeiling(policies), 25.0);
  policies.push_back(policy("tvlg", {true, false, true, false}));  // overlaps at trial 0: counted once
  EXPECT_DOUBLE_EQ(localPolicyCeiling(policies), 50.0);
}

TEST(PickupEvalHelpers, OptionRangesAreChecked) {
  Options o;
  o.policies = {{"a", "/x"}};
  EXPECT_NO_THROW(checkOptions(o));
  for (double step : {0.0, -1.0, 90.5, std::nan("")}) {
    Options bad = o;
    bad.sweep_step = step;
    EXPECT_THROW(checkOptions(bad), InputError) << step;
  }
  for (long long n : {0LL, 100001LL}) {
    Options bad = o;
    bad.random = n;
    EXPECT_THROW(checkOptions(bad), InputError) << n;
  }
  Options none;
  EXPECT_THROW(checkOptions(none), InputError);
  Options twice = o;
  twice.policies.push_back({"a", "/y"});
  EXPECT_THROW(checkOptions(twice), InputError);
}

// ---- the binary ----

struct ToolRun {
  int status = -1;
  std::string output;  // stdout and stderr
};

ToolRun runTool(const std::vector<std::string>& args) {
  std::vector<std::string> argv = {PICKUP_EVAL_BINARY};
  argv.insert(argv.end(), args.begin(), args.end());
  adroit::ProgramOptions options;
  options.timeout_s = 110.0;
  options.capture_output = true;
  options.merge_stderr = true;
  const adroit::ProgramResult r = adroit::runProgram(argv, options);
  return {r.exit_code, r.output + (r.ok() || r.exit_code > 0 ? "" : " [" + r.describe() + "]")};
}

std::vector<std::string> lines(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::string> out;
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

std::vector<std::string> fields(const std::string& line) {  // the test's rows have no quoted commas
  std::vector<std::string> out;
  std::stringstream in(line);
  for (std::string f; std::getline(in, f, ',');) out.push_back(f);
  if (!line.empty() && line.back() == ',') out.push_back("");
  return out;
}

// The pickup task on its scene, and trivial files for it: a TVLG with K = 0, k = 0 (the
// demonstration replay of a still demonstration), a library of it at 0 and 90 degrees, and the
// `demos export` text of a still demonstration with the tube at 30 degrees.
class PickupEvalTool : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    task_ = adroit::findTrainingTask(TASK_DIR, "pickup");
    scene_file_ = std::string(ADROIT_MJCF_DIR) + "/" + task_.scene + ".xml";
    dir_ = std::string(::testing::TempDir()) + "/pickup_eval_test";
    fs::remove_all(dir_);
    fs::create_directories(dir_ + "/demos");
    if (!fs::exists(scene_file_)) return;
    adroit::driver::SimConfig config;
    config.model_path = scene_file_;
    adroit::SimRollouts sim(config, 1);
    const adroit::StateLayout layout(task_, sim.jointNames(), sim.cylinderNames(), sim.hasObject());
    adroit::Demonstration still = stillDemonstration(sim, layout, 30.0);
    adroit::writePolicyFile(dir_ + "/zero.tvlg", adroit::demonstrationReplayPolicy(still, task_, layout));
    adroit::PolicyFile other = adroit::demonstrationReplayPolicy(still, task_, layout);
    other.task = "pickup_from_scratch";  // same robot and sizes, another task
    adroit::writePolicyFile(dir_ + "/other_task.tvlg", other);
    adroit::PolicyLibrary library;
    library.task = task_.name;
    library.scene = task_.scene;
    library.entries = {{0.0, "zero.tvlg", nullptr, ""}, {90.0, "zero.tvlg", nullptr, ""}};
    adroit::writePolicyLibrary(dir_ + "/library.txt", library);
    writeExport(dir_ + "/demos/still.txt", still);
    std::ofstream(dir_ + "/garbage.tvlg") << "hello\n";
  }

  // T + 1 samples of the task's initial state with the tube turned to `yaw`, all commands 0.
  static adroit::Demonstration stillDemonstration(adroit::SimRollouts& sim, const adroit::StateLayout& layout, double yaw) {
    adroit::Demonstration d;
    d.path = "still";
    d.task = task_.name, d.mode = "pneumatic", d.model = scene_file_, d.actions = "valve";
    d.joints = layout.joint_names, d.cylinders = layout.cylinder_names, d.has_object = true;
    d.dt = task_.control_dt;
    const Eigen::VectorXd x0 = sim.initialState(task_, layout);
    d.x = x0.replicate(1, task_.horizon + 1);
    const double half = yaw * M_PI / 360.0;
    d.x.block(layout.objectRotation(), 0, 3, d.x.cols()).setZero();
    d.x.row(layout.objectRotation() + 2).setConstant(2 * half);  // rotation vector about z (axis along body x)
    d.u = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(layout.cylinder_names.size()), task_.horizon + 1);
    return d;
  }

  static std::string names(const std::vector<std::string>& v) {
    std::string out;
    for (const auto& n : v) out += " " + n;
    return out;
  }

  // The text `demos export` writes (the header lines and blocks demonstration.h reads).
  static void writeExport(const std::string& path, const adroit::Demonstration& d) {
    std::ofstream out(path);
    out << std::setprecision(17) << "# adroit demonstration (x_t, u_t), written by adroit_teleop demos export\n"
        << "# task: " << d.task << "\n# mode: " << d.mode << "\n# model: " << d.model << "\n"
        << "# joints (" << d.joints.size() << "):" << names(d.joints) << "\n# cylinders (" << d.cylinders.size()
        << "):" << names(d.cylinders) << "\n# object: yes (/adroit/object/odom)\n# actions: valve [V]\n";
    out << "X " << d.x.cols() << " " << d.x.rows() << "\n" << d.x.transpose().format(Eigen::IOFormat(17)) << "\n";
    out << "U " << d.u.cols() << " " << d.u.rows() << "\n" << d.u.transpose().format(Eigen::IOFormat(17)) << "\n";
    out << "dt 1 1\n" << d.dt << "\n";
  }

  void SetUp() override { ASSERT_TRUE(fs::exists(scene_file_)) << "the task's scene file is missing: " << scene_file_; }

  std::vector<std::string> common(const std::string& out) const {
    return {"--task", "pickup", "--tasks-dir", TASK_DIR, "--scene-file", scene_file_, "--plot-script", PLOT_SCRIPT,
            "--out", out, "--workers", "2"};
  }

  static adroit::TrainingTask task_;
  static std::string scene_file_, dir_;
};

adroit::TrainingTask PickupEvalTool::task_;
std::string PickupEvalTool::scene_file_, PickupEvalTool::dir_;

TEST_F(PickupEvalTool, WritesEveryOutputForEveryKindOfInput) {
  const std::string out = dir_ + "/out";
  std::vector<std::string> args = common(out);
  for (const std::string& a : std::vector<std::string>{"--policy", "zero=" + dir_ + "/zero.tvlg", "--policy", "lib=" + dir_ + "/library.txt",
                               "--replay-demos", dir_ + "/demos", "--sweep-step", "45", "--random", "3",
                               "--cross-validate", dir_ + "/library.txt", "--trials", "2", "--require", "zero=0"})
    args.push_back(a);
  const ToolRun run = runTool(args);
  ASSERT_EQ(run.status, 0) << run.output;
  EXPECT_NE(run.output.find("RESULT adroit_learning/pickup_random_success/zero "), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("% target >= 0 PASS"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("INFO adroit_learning/pickup_random_success/lib "), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("INFO adroit_learning/pickup_random_success/demo_30 "), std::string::npos) << run.output;
  EXPECT_EQ(run.output.find("plots not written"), std::string::npos) << run.output;

  const auto sweep = lines(out + "/sweep.csv");
  ASSERT_EQ(sweep.size(), 1u + 3 * 4) << run.output;  // header + 3 policies x {0, 45, 90, 135}
  EXPECT_EQ(sweep[0], "policy,yaw_deg,success,cost,failure,selected_yaw");
  std::set<std::string> selected;
  for (std::size_t i = 1; i < sweep.size(); ++i) {
    const auto f = fields(sweep[i]);
    ASSERT_EQ(f.size(), 6u) << sweep[i];
    EXPECT_TRUE(f[2] == "0" || f[2] == "1") << sweep[i];
    EXPECT_FALSE(f[3].empty()) << sweep[i];  // every rollout ran to T: a cost
    if (f[0] == "lib") selected.insert(f[5]);
    else EXPECT_EQ(f[5], "") << sweep[i];
  }
  EXPECT_EQ(selected, (std::set<std::string>{"0", "90"}));  // 0 -> 0, 90 -> 90 (45 and 135 are ties)
  EXPECT_EQ(lines(out + "/random.csv").size(), 1u + 3 * 3);
  const auto summary = lines(out + "/summary.csv");
  ASSERT_EQ(summary.size(), 4u);
  EXPECT_NE(summary[2].find("lib,library,"), std::string::npos) << summary[2];
  EXPECT_NE(summary[2].find(",0 90,"), std::string::npos) << summary[2];      // the library's yaws
  EXPECT_NE(summary[3].find("demo_30,tvlg,"), std::string::npos) << summary[3];
  EXPECT_NE(summary[3].find(",30,"), std::string::npos) << summary[3];        // the demonstration's yaw
  EXPECT_GE(lines(out + "/summary.md").size(), 5u);
  const auto cross = lines(out + "/cross_validation.csv");
  ASSERT_EQ(cross.size(), 1u + 3 * 3);  // per policy: A (0), B (90), random
  EXPECT_EQ(fields(cross[1])[1], "A");
  EXPECT_EQ(fields(cross[1])[3], "2");
  EXPECT_EQ(fields(cross[3])[1], "random");
  EXPECT_TRUE(fs::exists(out + "/cross_validation.md"));
  for (const char* png : {"/sweep.png", "/random.png"}) {
    ASSERT_TRUE(fs::exists(out + png)) << png << "\n" << run.output;
    EXPECT_GT(fs::file_size(out + png), 1000u) << png;
  }
}

TEST_F(PickupEvalTool, AMissedTargetFailsTheExitStatusOnlyWithStrict) {
  std::vector<std::string> args = common(dir_ + "/strict");
  for (const std::string& a : std::vector<std::string>{"--policy", "zero=" + dir_ + "/zero.tvlg", "--sweep-step", "90",
                                                       "--random", "1", "--require", "zero=100", "--no-plot"})
    args.push_back(a);
  ToolRun run = runTool(args);
  EXPECT_EQ(run.status, 0) << run.output;  // the still hand picks nothing up
  EXPECT_NE(run.output.find("RESULT adroit_learning/pickup_random_success/zero 0 % target >= 100 FAIL"), std::string::npos)
      << run.output;
  args.push_back("--strict");
  run = runTool(args);
  EXPECT_EQ(run.status, 1) << run.output;
}

TEST_F(PickupEvalTool, BadInputIsOneLineAndExitStatusTwoBeforeAnythingRuns) {
  const std::string zero = "zero=" + dir_ + "/zero.tvlg";
  const std::vector<std::pair<std::vector<std::string>, std::string>> cases = {
      {{"--policy", zero, "--bogus"}, "unknown option '--bogus'"},
      {{"--policy", zero, "--sweep-step", "0"}, "--sweep-step must be in (0, 90]"},
      {{"--policy", zero, "--sweep-step", "90.5"}, "--sweep-step must be in (0, 90]"},
      {{"--policy", zero, "--random", "0"}, "--random must be in [1, 100000]"},
      {{"--policy", zero, "--random", "100001"}, "--random must be in [1, 100000]"},
      {{"--policy", "bad=" + dir_ + "/garbage.tvlg"}, "not a policy file"},
      {{"--policy", "gone=" + dir_ + "/missing.tvlg"}, "missing.tvlg"},
      {{"--policy", "other=" + dir_ + "/other_task.tvlg"}, "is a policy of task 'pickup_from_scratch'"},
      {{"--policy", zero, "--require", "nobody=50"}, "--require nobody: no policy of that name"},
      {{"--policy", "zero"}, "--policy needs NAME=VALUE"},
      {{}, "nothing to evaluate"},
  };
  for (const auto& [extra, expected] : cases) {
    const std::string out = dir_ + "/refused";
    fs::remove_all(out);
    std::vector<std::string> args = common(out);
    args.insert(args.end(), extra.begin(), extra.end());
    const ToolRun run = runTool(args);
    SCOPED_TRACE(expected);
    EXPECT_EQ(run.status, 2) << run.output;
    EXPECT_NE(run.output.find(expected), std::string::npos) << run.output;
    EXPECT_EQ(run.output.find("RESULT"), std::string::npos) << run.output;
    EXPECT_FALSE(fs::exists(out)) << "the refused run created its output directory";
    if (expected.rfind("unknown option", 0) != 0) {  // CommandLine adds its usage line
      EXPECT_EQ(std::count(run.output.begin(), run.output.end(), '\n'), 1) << run.output;
    }
  }
}

}  // namespace
