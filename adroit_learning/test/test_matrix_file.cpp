// MatrixFile: round trip at full precision, and one clear error (file, block, problem) for
// each kind of bad input instead of a crash.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>

#include "adroit_learning/matrix_file.h"
#include "lq_problems.h"

using adroit::MatrixFile;
using adroit::MatrixFileError;
using Eigen::MatrixXd;

namespace {
// The message of the MatrixFileError thrown by f ("" if none).
template <typename F>
std::string errorOf(F f) {
  try {
    f();
  } catch (const MatrixFileError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(MatrixFile, RoundTripsAtFullPrecision) {
  std::mt19937 rng(1);
  const adroit::LgDynamics dyn = test_problems::randomDynamics(rng, 3, 2, 4);
  MatrixFile file("dyn.txt");
  adroit::writeDynamics(dyn, file);
  const adroit::LgDynamics back = adroit::readDynamics(MatrixFile::parse(file.text(), "dyn.txt"));
  ASSERT_EQ(back.horizon, 4);
  EXPECT_EQ(back.x0_mean, dyn.x0_mean);
  for (int t = 0; t < 4; ++t) {
    EXPECT_EQ(back.Fx[t], dyn.Fx[t]);  // bit-exact with %.17g
    EXPECT_EQ(back.Sigma[t], dyn.Sigma[t]);
  }
}

TEST(MatrixFile, ParsesCommentsAndFreeLayout) {
  const MatrixFile f = MatrixFile::parse("# header\nA 2 2  # a comment\n1 2\n3\n4e-1\nb 1 1 -5\n", "x.txt");
  EXPECT_EQ(f.get("A", 2, 2), (MatrixXd(2, 2) << 1, 2, 3, 0.4).finished());
  EXPECT_EQ(f.get("b")(0, 0), -5.0);
}

TEST(MatrixFile, BadInputGivesAClearError) {
  const auto parse = [](const std::string& text) { return [text] { MatrixFile::parse(text, "in.txt"); }; };
  std::string e = errorOf(parse("A 2 2\n1 2 nan 4\n"));
  EXPECT_NE(e.find("in.txt:1: block 'A'"), std::string::npos) << e;
  EXPECT_NE(e.find("entry (1, 0) on line 2 is not finite: 'nan'"), std::string::npos) << e;
  e = errorOf(parse("A 2 2\n1 2 inf 4\n"));
  EXPECT_NE(e.find("not finite"), std::string::npos) << e;
  e = errorOf(parse("A 2 2\n1 2 x 4\n"));
  EXPECT_NE(e.find("is not a number: 'x'"), std::string::npos) << e;
  e = errorOf(parse("A 2 2\n1 2 3\n"));
  EXPECT_NE(e.find("block 'A': the file ends after 3 of its 4 numbers"), std::string::npos) << e;
  e = errorOf(parse("A 2\n"));
  EXPECT_NE(e.find("block 'A': the header must be"), std::string::npos) << e;
  e = errorOf(parse("A 0 3\n"));
  EXPECT_NE(e.find("not positive"), std::string::npos) << e;
  e = errorOf(parse("A 1 1 1\nA 1 1 2\n"));
  EXPECT_NE(e.find("in.txt:2: block 'A': appears twice"), std::string::npos) << e;
  e = errorOf([] { MatrixFile::read("/nonexistent/dir/f.txt"); });
  EXPECT_NE(e.find("/nonexistent/dir/f.txt: cannot open"), std::string::npos) << e;

  const MatrixFile f = MatrixFile::parse("A 2 3\n1 2 3 4 5 6\n", "in.txt");
  e = errorOf([&] { f.get("A", 3, 2); });
  EXPECT_EQ(e, "in.txt: block 'A': is 2x3, expected 3x2");
  e = errorOf([&] { f.get("B"); });
  EXPECT_EQ(e, "in.txt: block 'B': missing");
}

TEST(MatrixFile, ControllerCovarianceMustBePositiveDefinite) {
  adroit::LgController c(2, 2, 1);
  MatrixFile file("prev.txt");
  adroit::writeController(c, file);
  file.set("C.0", (MatrixXd(2, 2) << 1, 3, 3, 1).finished());
  const std::string e = errorOf([&] { adroit::readController(file, 2, 2, 1); });
  EXPECT_EQ(e, "prev.txt: block 'C.0': not a symmetric positive definite covariance");
  const std::string dims = errorOf([&] { adroit::readController(file, 3, 2, 1); });
  EXPECT_NE(dims.find("prev.txt: block 'dims'"), std::string::npos) << dims;
}

namespace {
// A fresh directory for file-type tests, removed at the end.
struct TempDir {
  std::string path;
  TempDir() {
    char tmpl[] = "/tmp/matrix_file_test_XXXXXX";
    path = mkdtemp(tmpl) ? tmpl : "/tmp";
  }
  ~TempDir() { std::filesystem::remove_all(path); }
};

double secondsOf(const std::function<void()>& f) {
  const auto start = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}
}  // namespace

TEST(MatrixFile, ABadHeaderNamesTheBlockWithTooManyNumbers) {
  std::string e = errorOf([] { MatrixFile::parse("Sigma 2 2\n1 0 0 1 0.5\nB 1 1 2\n", "in.txt"); });
  EXPECT_EQ(e, "in.txt:2: block 'Sigma' (2x2): the number '0.5' follows its last number where the next header should "
               "be (more numbers than its shape?)");
  e = errorOf([] { MatrixFile::parse("3 1 1\n", "in.txt"); });
  EXPECT_NE(e.find("the number '3' where the first block header"), std::string::npos) << e;
}

TEST(MatrixFile, HugeShapesAreRefusedBeforeAllocating) {
  // 1e5 x 1e5 doubles would be 80 GB: refused from the bytes that follow, at once.
  std::string e;
  EXPECT_LT(secondsOf([&] { e = errorOf([] { MatrixFile::parse("A 100000 100000\n1 2 3\n", "in.txt"); }); }), 0.5);
  EXPECT_NE(e.find("in.txt:1: block 'A': shape 100000x100000 needs 10000000000 numbers, more than the"),
            std::string::npos)
      << e;
  // A dims block claiming T = 1e6 with one step's blocks: refused before the horizon is allocated.
  adroit::LgController c(2, 2, 1);
  MatrixFile file("prev.txt");
  adroit::writeController(c, file);
  file.set("dims", (MatrixXd(1, 3) << 2, 2, 1000000).finished());
  EXPECT_LT(secondsOf([&] { e = errorOf([&] { adroit::readController(file, 2, 2, 1000000); }); }), 0.5);
  EXPECT_EQ(e, "prev.txt: T = 1000000 needs 3000000 per-step blocks, the file has 4 blocks in all");
  file.set("dims", (MatrixXd(1, 3) << 2, 2, 1e7).finished());
  e = errorOf([&] { adroit::readDims(file); });
  EXPECT_NE(e.find("prev.txt: block 'dims': nx, nu and T must be whole numbers"), std::string::npos) << e;
}

TEST(MatrixFile, OnlyRegularFilesWithinTheLimitAreRead) {
  TempDir dir;
  const std::string fifo = dir.path + "/fifo";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  std::string e;
  EXPECT_LT(secondsOf([&] { e = errorOf([&] { MatrixFile::read(fifo); }); }), 0.5);  // no writer: must not block
  EXPECT_EQ(e, fifo + ": not a regular file (a FIFO)");
  EXPECT_EQ(errorOf([] { MatrixFile::read("/dev/zero"); }), "/dev/zero: not a regular file (a character device)");
  EXPECT_EQ(errorOf([&] { MatrixFile::read(dir.path); }), dir.path + ": not a regular file (a directory)");
  const std::string big = dir.path + "/big.txt";
  { std::ofstream(big) << "A 1 1 1\n"; }
  std::filesystem::resize_file(big, adroit::kMaxMatrixFileBytes + 1);  // sparse: no disk used
  e = errorOf([&] { MatrixFile::read(big); });
  EXPECT_NE(e.find(big + ": 256 MB (268435457 bytes), over the limit of 256 MB (268435456 bytes)"), std::string::npos) << e;
}

TEST(MatrixFile, CovarianceMustBeSymmetricPositiveSemiDefinite) {
  EXPECT_EQ(adroit::covarianceProblem(MatrixXd::Identity(3, 3)), "");
  EXPECT_EQ(adroit::covarianceProblem(MatrixXd::Zero(3, 3)), "");  // a deterministic start
  EXPECT_EQ(adroit::covarianceProblem((MatrixXd(2, 2) << 1, 2, 2, 1).finished()),
            "not positive semi-definite: its LDLT factorisation has the pivot -3.000000");
  EXPECT_EQ(adroit::covarianceProblem((MatrixXd(2, 2) << 1, 0.5, 0, 1).finished()),
            "not symmetric: entries (1, 0) and (0, 1) differ by 0.500000");
}
