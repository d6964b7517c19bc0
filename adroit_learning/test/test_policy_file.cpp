// Policy files: what is written reads back the same; a damaged or foreign file is refused
// naming the file and the problem; a failed write leaves no temporary behind.
#include <adroit_learning/policy_file.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace {

adroit::PolicyFile examplePolicy() {
  adroit::PolicyFile p;
  p.task = "position_with_gravity";
  p.scene = "hand";
  p.state_layout = "q:2 qdot:2 pressure_bar_gauge:3";
  p.control_dt = 0.04;
  p.iteration = 7;
  p.cost_mean = 12.5;
  p.joints = {"FFJ1", "FFJ2"};
  p.cylinders = {"A_a", "A_b", "A_c"};
  p.actions = {"A_a", "A_c"};
  p.locked_command = 0.5;
  p.controller = adroit::LgController(7, 2, 3);
  for (int t = 0; t < 3; ++t) {
    p.controller.K[t] = Eigen::MatrixXd::Random(2, 7);
    p.controller.k[t] = Eigen::VectorXd::Random(2);
    p.controller.setCovariance(t, (Eigen::MatrixXd(2, 2) << 2.0 + t, 0.3, 0.3, 1.0).finished());
  }
  return p;
}

std::string tempPath(const std::string& name) { return std::string(::testing::TempDir()) + "/" + name; }

std::string readError(const std::string& path) {
  try {
    adroit::readPolicyFile(path);
  } catch (const adroit::PolicyFileError& e) {
    return e.what();
  }
  return "";
}

std::string fileText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

}  // namespace

TEST(PolicyFile, RoundTrip) {
  const adroit::PolicyFile p = examplePolicy();
  const std::string path = tempPath("p.tvlg");
  adroit::writePolicyFile(path, p);
  const adroit::PolicyFile q = adroit::readPolicyFile(path);
  EXPECT_EQ(q.task, p.task);
  EXPECT_EQ(q.scene, p.scene);
  EXPECT_EQ(q.state_layout, p.state_layout);
  EXPECT_EQ(q.joints, p.joints);
  EXPECT_EQ(q.cylinders, p.cylinders);
  EXPECT_EQ(q.actions, p.actions);
  EXPECT_EQ(q.iteration, 7);
  EXPECT_DOUBLE_EQ(q.control_dt, 0.04);
  EXPECT_DOUBLE_EQ(q.cost_mean, 12.5);
  EXPECT_DOUBLE_EQ(q.locked_command, 0.5);
  ASSERT_EQ(q.controller.horizon(), 3);
  for (int t = 0; t < 3; ++t) {
    EXPECT_EQ(q.controller.K[t], p.controller.K[t]);  // written at full precision
    EXPECT_EQ(q.controller.k[t], p.controller.k[t]);
    EXPECT_EQ(q.controller.covariance(t), p.controller.covariance(t));
  }
}

TEST(PolicyFile, DamagedFilesAreRefusedNamingTheProblem) {
  const std::string path = tempPath("d.tvlg");
  adroit::writePolicyFile(path, examplePolicy());
  const std::string text = fileText(path);

  std::ofstream(path) << text.substr(0, text.size() * 2 / 3);  // cut inside the matrices
  std::string e = readError(path);
  EXPECT_NE(e.find(path), std::string::npos) << e;
  EXPECT_FALSE(e.empty());

  std::ofstream(path) << text.substr(0, text.find("matrices"));
  e = readError(path);
  EXPECT_NE(e.find("truncated"), std::string::npos) << e;

  std::string other = text;
  other.replace(0, std::string("adroit_tvlg_policy 1").size(), "adroit_tvlg_policy 9");
  std::ofstream(path) << other;
  e = readError(path);
  EXPECT_NE(e.find("format version 9"), std::string::npos) << e;

  std::ofstream(path) << "hello world\n";
  e = readError(path);
  EXPECT_NE(e.find("not an adroit_learning policy"), std::string::npos) << e;

  std::string bad_cov = text;
  const auto c0 = bad_cov.find("C.0 2 2\n");
  bad_cov.insert(bad_cov.find('\n', c0) + 1, "-");  // C.0(0,0) negative: not a covariance
  std::ofstream(path) << bad_cov;
  e = readError(path);
  EXPECT_NE(e.find("C.0"), std::string::npos) << e;

  EXPECT_NE(readError(tempPath("missing.tvlg")).find("cannot open"), std::string::npos);
}

TEST(PolicyFile, MismatchNamesWhatDiffers) {
  const adroit::PolicyFile p = examplePolicy();
  EXPECT_EQ(adroit::policyMismatch(p, "f", p.joints, p.cylinders, p.state_layout), "");
  const std::string joints = adroit::policyMismatch(p, "f", {"FFJ1", "MFJ2"}, p.cylinders, p.state_layout);
  EXPECT_NE(joints.find("'FFJ2' where the robot has 'MFJ2'"), std::string::npos) << joints;
  const std::string cylinders = adroit::policyMismatch(p, "f", p.joints, {"A_a"}, p.state_layout);
  EXPECT_NE(cylinders.find("cylinders differ"), std::string::npos) << cylinders;
  const std::string layout = adroit::policyMismatch(p, "f", p.joints, p.cylinders, "q:2");
  EXPECT_NE(layout.find("state layout"), std::string::npos) << layout;
}

TEST(PolicyFile, FailedReplaceKeepsTheTargetAndLeavesNoTemporary) {
  // A directory where the file should go: rename() fails; the directory and its content stay.
  const std::string dir = tempPath("policy_dir_target");
  ::mkdir(dir.c_str(), 0755);
  std::ofstream(dir + "/keep") << "x";
  try {
    adroit::writePolicyFile(dir, examplePolicy());
    FAIL() << "no error";
  } catch (const adroit::PolicyFileError& e) {
    EXPECT_NE(std::string(e.what()).find(dir), std::string::npos) << e.what();
  }
  EXPECT_EQ(fileText(dir + "/keep"), "x");
  struct stat st;
  EXPECT_NE(::stat((dir + ".tmp." + std::to_string(::getpid())).c_str(), &st), 0);
  EXPECT_THROW(adroit::writePolicyFile(tempPath("no/such/dir/p.tvlg"), examplePolicy()), adroit::PolicyFileError);
}

namespace {
double secondsToRead(const std::string& path, std::string& error) {
  const auto start = std::chrono::steady_clock::now();
  error = readError(path);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}
}  // namespace

TEST(PolicyFile, AHugeHorizonInASmallFileIsRefusedWithoutAllocating) {
  // T = 1e6 at nx 88, nu 40 would be ~54 GB: before, it was allocated before the blocks were
  // looked for (std::bad_alloc, or the machine's memory).
  adroit::PolicyFile p = examplePolicy();
  p.actions.resize(40, "A_a");
  p.controller = adroit::LgController::initial(88, 1, Eigen::VectorXd::Zero(40), Eigen::VectorXd::Constant(40, 0.3));
  const std::string path = tempPath("huge_t.tvlg");
  adroit::writePolicyFile(path, p);
  std::string text = fileText(path);
  const std::string dims = "dims 1 3\n88 40 1\n";
  ASSERT_NE(text.find(dims), std::string::npos);
  text.replace(text.find(dims), dims.size(), "dims 1 3\n88 40 1000000\n");
  std::ofstream(path) << text;
  std::string e;
  EXPECT_LT(secondsToRead(path, e), 1.0);
  EXPECT_EQ(e, path + ": T = 1000000 needs 3000000 per-step blocks, the file has 4 blocks in all");
}

TEST(PolicyFile, OnlyRegularFilesWithinTheLimitAreRead) {
  const std::string fifo = tempPath("policy.fifo");
  ::unlink(fifo.c_str());
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  std::string e;
  EXPECT_LT(secondsToRead(fifo, e), 0.5);  // no writer: a plain open would block for good
  EXPECT_EQ(e, fifo + ": not a regular file (a FIFO)");
  ::unlink(fifo.c_str());
  EXPECT_EQ(readError("/dev/zero"), "/dev/zero: not a regular file (a character device)");
  const std::string dir = tempPath("policy_is_a_dir");
  ::mkdir(dir.c_str(), 0755);
  EXPECT_EQ(readError(dir), dir + ": not a regular file (a directory)");  // was "empty file"
  const std::string big = tempPath("big.tvlg");
  adroit::writePolicyFile(big, examplePolicy());
  std::filesystem::resize_file(big, adroit::kMaxPolicyFileBytes + 1);  // sparse
  EXPECT_EQ(readError(big), big + ": 256 MB (268435457 bytes), over the limit of 256 MB (268435456 bytes)");
  ::unlink(big.c_str());
}
