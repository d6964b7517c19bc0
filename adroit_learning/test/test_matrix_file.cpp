// MatrixFile: round trip at full precision, and one clear error (file, block, problem) for
// each kind of bad input instead of a crash.
#include <gtest/gtest.h>

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
