// Policies of thesis ch. 11 as the stack runs them: a TVLG file's mean action, the
// nearest-neighbour library of 11.5 (angles modulo 180 degrees, the tube's yaw read back from
// its orientation, the library file and what it refuses, the choice at start) and the loader
// that dispatches on a file's first word.
#include <adroit_learning/policy_library.h>
#include <adroit_learning/policy_loader.h>
#include <adroit_learning/trajectory_cost.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

namespace {

const std::vector<std::string> kJoints = {"J0", "J1"};
const std::vector<std::string> kCylinders = {"C0", "C1", "C2"};

// A task whose state has the object (its height is in the cost).
adroit::TrainingTask objectTask() {
  adroit::TrainingTask task;
  task.name = "pickup";
  task.scene = "tube";
  task.horizon = 4;
  task.control_dt = 0.04;
  task.object_height_weight = 1.0;
  return task;
}

adroit::StateLayout objectLayout() { return adroit::StateLayout(objectTask(), kJoints, kCylinders, true); }

// A TVLG policy of `task` on objectLayout() with random gains (different per seed).
adroit::PolicyFile tvlgFile(unsigned seed, const std::string& task = "pickup", int horizon = 4) {
  const adroit::StateLayout layout = objectLayout();
  std::srand(seed);
  adroit::PolicyFile p;
  p.task = task;
  p.scene = "tube";
  p.state_layout = layout.describe();
  p.control_dt = 0.04;
  p.joints = kJoints;
  p.cylinders = kCylinders;
  p.actions = kCylinders;
  p.controller = adroit::LgController(layout.nx(), layout.nu(), horizon);
  for (int t = 0; t < horizon; ++t) {
    p.controller.K[t] = Eigen::MatrixXd::Random(layout.nu(), layout.nx());
    p.controller.k[t] = Eigen::VectorXd::Random(layout.nu());
  }
  return p;
}

// A fresh directory for one test's files.
std::string testDirectory(const std::string& name) {
  const std::string dir = std::string(::testing::TempDir()) + "/policy_library_" + name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

void writeText(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

std::string libraryError(const std::string& path) {
  try {
    adroit::readPolicyLibrary(path);
  } catch (const adroit::PolicyFileError& e) {
    return e.what();
  }
  return "";
}

std::string loadError(const std::string& path, const adroit::PolicyContext& context = {}) {
  try {
    adroit::loadPolicy(path, context);
  } catch (const adroit::PolicyFileError& e) {
    return e.what();
  }
  return "";
}

// Two local policies (yaw 0 in a subdirectory, yaw 90 by absolute path) and their library.
struct LibraryFiles {
  explicit LibraryFiles(const std::string& name) : dir(testDirectory(name)), path(dir + "/pickup.library") {
    std::filesystem::create_directories(dir + "/yaw000");
    adroit::writePolicyFile(dir + "/yaw000/final.tvlg", tvlgFile(1));
    adroit::writePolicyFile(dir + "/yaw090.tvlg", tvlgFile(2));
    library.task = "pickup";
    library.scene = "tube";
    library.entries = {{0.0, "yaw000/final.tvlg", nullptr, ""}, {90.0, dir + "/yaw090.tvlg", nullptr, ""}};
    adroit::writePolicyLibrary(path, library);
  }
  std::string dir, path;
  adroit::PolicyLibrary library;
};

adroit::ObjectGeometry tube() {
  adroit::ObjectGeometry g;
  g.half_length = 0.12;
  g.radius = 0.02;
  return g;
}

// A state of objectLayout() with the tube lying at `yaw_deg` (other entries arbitrary).
Eigen::VectorXd stateWithTubeAt(double yaw_deg) {
  const adroit::StateLayout layout = objectLayout();
  Eigen::VectorXd x = Eigen::VectorXd::LinSpaced(layout.nx(), -1.0, 1.0);
  const Eigen::Quaterniond q = adroit::tubeOrientationFromYaw(yaw_deg, tube());
  const double wxyz[4] = {q.w(), q.x(), q.y(), q.z()};
  x.segment<3>(layout.objectRotation()) = adroit::rotationVector(wxyz);
  return x;
}

double angularDistance180(double a, double b) {
  const double d = std::fmod(std::abs(a - b), 180.0);
  return std::min(d, 180.0 - d);
}

}  // namespace

TEST(NearestPolicy, AnglesWrapAt180AndTiesGoToTheLowerIndex) {
  const std::vector<double> yaws = {0, 90, 170};
  EXPECT_EQ(adroit::nearestPolicyIndex(yaws, 178), 0);  // 2 from 0 across 180, 8 from 170
  EXPECT_EQ(adroit::nearestPolicyIndex(yaws, 95), 1);
  EXPECT_EQ(adroit::nearestPolicyIndex(yaws, 172), 2);
  EXPECT_EQ(adroit::nearestPolicyIndex(yaws, 0), 0);
  EXPECT_EQ(adroit::nearestPolicyIndex(yaws, -3), 0);   // outside [0, 180) still modulo 180
  EXPECT_EQ(adroit::nearestPolicyIndex(yaws, 351), 2);  // 171
  EXPECT_EQ(adroit::nearestPolicyIndex({0, 90}, 45), 0);   // tie
  EXPECT_EQ(adroit::nearestPolicyIndex({0, 90}, 135), 0);  // tie across the wrap
  EXPECT_EQ(adroit::nearestPolicyIndex({90, 0}, 45), 0);   // the lower index, not the lower angle
  EXPECT_EQ(adroit::nearestPolicyIndex({10, 170}, 0), 0);  // 10 either way
  EXPECT_EQ(adroit::nearestPolicyIndex({}, 10), -1);
  EXPECT_EQ(adroit::nearestPolicyIndex(yaws, std::numeric_limits<double>::quiet_NaN()), -1);
}

TEST(TubeYaw, InvertsTubeOrientationFromYawOverTheRange) {
  adroit::ObjectGeometry along_z = tube();
  along_z.axis_in_body = Eigen::Vector3d::UnitZ();  // a capsule along its geom's z
  for (const adroit::ObjectGeometry& g : {tube(), along_z}) {
    for (double yaw : {0.0, 1e-9, 0.5, 45.0, 89.99, 90.0, 135.0, 179.5, 179.999999, 180.0 - 1e-12})
      EXPECT_LT(angularDistance180(adroit::tubeYawDegrees(adroit::tubeOrientationFromYaw(yaw, g), g), yaw), 1e-9)
          << yaw;
    for (double yaw = 0; yaw < 180; yaw += 7.3) {
      const double back = adroit::tubeYawDegrees(adroit::tubeOrientationFromYaw(yaw, g), g);
      EXPECT_GE(back, 0.0);
      EXPECT_LT(back, 180.0);
      EXPECT_NEAR(back, yaw, 1e-9);
    }
  }
  // A tube lifted at one end keeps the yaw of its horizontal projection; upright it has none.
  const Eigen::Vector3d across(-std::sin(M_PI / 6), std::cos(M_PI / 6), 0);
  const Eigen::Quaterniond tilted = Eigen::AngleAxisd(0.4, across) * adroit::tubeOrientationFromYaw(30, tube());
  EXPECT_NEAR(adroit::tubeYawDegrees(tilted, tube()), 30.0, 1e-9);
  const Eigen::Quaterniond upright(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()));
  EXPECT_THROW(adroit::tubeYawDegrees(upright, tube()), std::invalid_argument);
}

TEST(PolicyLibraryFile, RoundTrip) {
  const LibraryFiles files("round_trip");
  const adroit::PolicyLibrary read = adroit::readPolicyLibrary(files.path);
  EXPECT_EQ(read.task, "pickup");
  EXPECT_EQ(read.scene, "tube");
  ASSERT_EQ(read.entries.size(), 2u);
  EXPECT_EQ(read.yaws(), (std::vector<double>{0.0, 90.0}));
  for (std::size_t i = 0; i < 2; ++i) EXPECT_EQ(read.entries[i].path, files.library.entries[i].path);
  EXPECT_EQ(read.entries[0].resolved_path, files.dir + "/yaw000/final.tvlg");  // relative to the library
  EXPECT_EQ(read.entries[0].policy->controller.K[2], tvlgFile(1).controller.K[2]);
  EXPECT_EQ(read.entries[1].policy->controller.k[3], tvlgFile(2).controller.k[3]);
}

TEST(PolicyLibraryFile, RefusesWhatCannotBeALibrary) {
  const LibraryFiles files("refusals");
  adroit::writePolicyFile(files.dir + "/other_task.tvlg", tvlgFile(3, "rotate_vertical_cw"));
  adroit::writePolicyFile(files.dir + "/short.tvlg", tvlgFile(4, "pickup", 3));
  const std::string head = "adroit_policy_library 1\ntask pickup\nscene tube\n";
  const std::string path = files.dir + "/bad.library";
  const auto refusal = [&](const std::string& text) {
    writeText(path, text);
    return libraryError(path);
  };
  EXPECT_EQ(refusal(head), path + ": library has no policies");
  EXPECT_NE(refusal(head + "policy nan yaw090.tvlg\n").find("angle must be in [0, 180) degrees, got nan"),
            std::string::npos);
  EXPECT_NE(refusal(head + "policy 180 yaw090.tvlg\n").find("got 180"), std::string::npos);
  EXPECT_NE(refusal(head + "policy 10 yaw090.tvlg\npolicy 10.0 yaw000/final.tvlg\n").find("the same angle 10"),
            std::string::npos);
  const std::string missing = refusal(head + "policy 0 missing.tvlg\n");
  EXPECT_EQ(missing.rfind(path + ": " + files.dir + "/missing.tvlg: cannot open", 0), 0u) << missing;
  EXPECT_NE(refusal(head + "policy 0 yaw090.tvlg\npolicy 30 other_task.tvlg\n")
                .find("other_task.tvlg: task 'rotate_vertical_cw', the library's is 'pickup'"),
            std::string::npos);
  EXPECT_NE(refusal(head + "policy 0 yaw090.tvlg\npolicy 30 short.tvlg\n").find("horizon 3"), std::string::npos);
  EXPECT_NE(refusal("adroit_policy_library 2\n").find("format version 2"), std::string::npos);
  EXPECT_NE(refusal(head + "polcy 0 yaw090.tvlg\n").find("line 4: unknown key 'polcy'"), std::string::npos);
  EXPECT_NE(refusal("adroit_tvlg_policy 1\n").find("not a policy library"), std::string::npos);
  EXPECT_NE(refusal("adroit_policy_library 1\npolicy 0 yaw090.tvlg\n").find("'task' and 'scene'"), std::string::npos);
  // A FIFO is refused at once, never read (a read would block with no writer).
  const std::string fifo = files.dir + "/library.fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const auto start = std::chrono::steady_clock::now();
  EXPECT_EQ(libraryError(fifo), fifo + ": not a regular file (a FIFO)");
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 1.0);
  // Writing refuses what reading would.
  adroit::PolicyLibrary bad = files.library;
  bad.entries[1].yaw_deg = 0.0;
  EXPECT_THROW(adroit::writePolicyLibrary(files.dir + "/dup.library", bad), adroit::PolicyFileError);
  EXPECT_FALSE(std::filesystem::exists(files.dir + "/dup.library"));
}

TEST(TvlgPolicy, ActsAsTheControllersMean) {
  const adroit::PolicyFile file = tvlgFile(5);
  adroit::TvlgPolicy policy(file, "p.tvlg");
  EXPECT_EQ(policy.kind(), "tvlg");
  EXPECT_EQ(policy.horizon(), 4);
  const adroit::StateLayout layout = objectLayout();
  const Eigen::VectorXd x = Eigen::VectorXd::Random(layout.nx()), touch;
  Eigen::VectorXd u(layout.nu()), mean(layout.nu());
  for (int t = 0; t < 4; ++t) {
    policy.action(t, x, touch, u);
    file.controller.action(t, x, Eigen::VectorXd::Zero(layout.nu()), mean);
    EXPECT_EQ(u, mean) << t;
  }
  EXPECT_THROW(policy.action(4, x, touch, u), std::invalid_argument);  // past T
  Eigen::VectorXd short_u(2);
  EXPECT_THROW(policy.action(0, x, touch, short_u), std::invalid_argument);
  EXPECT_EQ(policy.mismatch(kJoints, kCylinders, {}, layout), "");
  EXPECT_NE(policy.mismatch({"J0", "J9"}, kCylinders, {}, layout).find("p.tvlg: joints differ"), std::string::npos);
  adroit::TrainingTask locked = objectTask();
  locked.locked_cylinders = {"C1"};
  EXPECT_NE(policy.mismatch(kJoints, kCylinders, {}, adroit::StateLayout(locked, kJoints, kCylinders, true))
                .find("acts on 3 cylinders"),
            std::string::npos);
}

TEST(LibraryPolicy, StartPicksByTheTubesYawAndDelegates) {
  const LibraryFiles files("select");
  adroit::LibraryPolicy policy(std::make_shared<const adroit::PolicyLibrary>(adroit::readPolicyLibrary(files.path)),
                               tube(), files.path);
  EXPECT_EQ(policy.kind(), "library");
  EXPECT_EQ(policy.horizon(), 4);
  EXPECT_EQ(policy.selected(), -1);
  const adroit::StateLayout layout = objectLayout();
  EXPECT_EQ(policy.mismatch(kJoints, kCylinders, {}, layout), "");
  adroit::TrainingTask no_object = objectTask();
  no_object.object_height_weight = 0;
  EXPECT_NE(policy.mismatch(kJoints, kCylinders, {}, adroit::StateLayout(no_object, kJoints, kCylinders, false))
                .find("no object"),
            std::string::npos);
  Eigen::VectorXd u(layout.nu()), expected(layout.nu());
  const Eigen::VectorXd touch;
  EXPECT_THROW(policy.action(0, stateWithTubeAt(10), touch, u), std::logic_error);  // before start
  const struct {
    double observed, selected_yaw;
    int index;
    unsigned seed;
  } cases[] = {{85, 90, 1, 2}, {30, 0, 0, 1}, {178, 0, 0, 1}, {134, 90, 1, 2}, {136, 0, 0, 1}};
  for (const auto& c : cases) {
    const Eigen::VectorXd x0 = stateWithTubeAt(c.observed);
    policy.start(x0);
    EXPECT_EQ(policy.selected(), c.index) << c.observed;
    EXPECT_EQ(policy.selectedYaw(), c.selected_yaw);
    EXPECT_NEAR(policy.observedYaw(), c.observed, 1e-9);
    const adroit::PolicyFile local = tvlgFile(c.seed);
    for (int t = 0; t < 4; ++t) {
      policy.action(t, x0, touch, u);
      expected = local.controller.k[t] + local.controller.K[t] * x0;
      EXPECT_TRUE(u.isApprox(expected, 1e-12)) << c.observed << " step " << t;
    }
  }
}

TEST(PolicyLoader, DispatchesOnTheFirstWord) {
  const LibraryFiles files("loader");
  adroit::PolicyOrigin origin;
  std::unique_ptr<adroit::Policy> tvlg = adroit::loadPolicy(files.dir + "/yaw090.tvlg", {}, &origin);
  EXPECT_EQ(tvlg->kind(), "tvlg");
  EXPECT_EQ(origin.format, "adroit_tvlg_policy");
  EXPECT_EQ(origin.task, "pickup");
  EXPECT_EQ(origin.scene, "tube");
  EXPECT_DOUBLE_EQ(origin.control_dt, 0.04);
  std::string asked_scene;
  const adroit::PolicyContext context{[&](const std::string& scene) {
    asked_scene = scene;
    return tube();
  }};
  std::unique_ptr<adroit::Policy> library = adroit::loadPolicy(files.path, context, &origin);
  EXPECT_EQ(library->kind(), "library");
  EXPECT_EQ(asked_scene, "tube");
  EXPECT_EQ(origin.format, "adroit_policy_library");
  EXPECT_EQ(origin.task, "pickup");
  EXPECT_DOUBLE_EQ(origin.control_dt, 0.04);
  EXPECT_NE(loadError(files.path).find("needs the scene's object geometry"), std::string::npos);
  const std::string network = files.dir + "/net.policy";
  writeText(network, "adroit_network_policy 1\ntask pickup\n");
  EXPECT_EQ(loadError(network), network + ": network policies need adroit_learning_network");
  const std::string unknown = files.dir + "/notes.txt";
  writeText(unknown, "hello\x01 world\nmore\n");
  EXPECT_EQ(loadError(unknown), unknown + ": not a policy file (first line 'hello? world')");
  const std::string empty = files.dir + "/empty.tvlg";
  writeText(empty, "");
  EXPECT_EQ(loadError(empty), empty + ": empty file");
  EXPECT_EQ(loadError(files.dir), files.dir + ": not a regular file (a directory)");
  EXPECT_NE(loadError(files.dir + "/none.tvlg").find("none.tvlg: cannot open"), std::string::npos);
  // A registered reader (as adroit_learning_network registers its own) is used for its word.
  adroit::registerPolicyReader("adroit_test_policy", [](const std::string& path, const adroit::PolicyContext&,
                                                        adroit::PolicyOrigin& o) -> std::unique_ptr<adroit::Policy> {
    o.task = "test";
    return std::make_unique<adroit::TvlgPolicy>(tvlgFile(6), path);
  });
  const std::string test_policy = files.dir + "/test.policy";
  writeText(test_policy, "adroit_test_policy 1\n");
  EXPECT_EQ(adroit::loadPolicy(test_policy, {}, &origin)->kind(), "tvlg");
  EXPECT_EQ(origin.format, "adroit_test_policy");
  EXPECT_EQ(origin.task, "test");
}
