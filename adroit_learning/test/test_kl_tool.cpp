// The kl_update tool (run as a process): its output equals the library's update on the same
// inputs, and bad input files end it with a non-zero status and a message naming the file,
// the block and the problem.
#include <adroit_core/run_program.h>
#include <sys/stat.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "adroit_learning/kl_update.h"
#include "adroit_learning/matrix_file.h"
#include "lq_problems.h"

using namespace adroit;

namespace {

struct ToolRun {
  int status;
  std::string output;  // stdout and stderr
};

// The tool with `args` split at spaces (the test's paths have none), as an argument vector.
ToolRun runTool(const std::string& args) {
  std::vector<std::string> argv = {KL_UPDATE_BINARY};
  std::istringstream words(args);
  for (std::string w; words >> w;) argv.push_back(w);
  adroit::ProgramOptions options;
  options.timeout_s = 120.0;
  options.capture_output = true;
  options.merge_stderr = true;
  const adroit::ProgramResult r = adroit::runProgram(argv, options);
  return {r.exit_code, r.output + (r.ok() ? "" : " [" + r.describe() + "]")};
}

void writeText(const std::string& path, const std::string& text) {
  FILE* f = std::fopen(path.c_str(), "w");
  ASSERT_NE(f, nullptr);
  std::fputs(text.c_str(), f);
  std::fclose(f);
}

class KlTool : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/kl_tool_test_XXXXXX";
    ASSERT_NE(mkdtemp(tmpl), nullptr);
    dir_ = tmpl;
    std::mt19937 rng(21);
    dyn_ = test_problems::randomDynamics(rng, nx_, nu_, T_);
    cost_ = test_problems::randomCost(rng, nx_, nu_, T_);
    prev_ = LgController::initial(nx_, T_, Eigen::VectorXd::Zero(nu_), Eigen::VectorXd::Constant(nu_, 0.3));
    MatrixFile d("dyn"), c("cost"), p("prev");
    writeDynamics(dyn_, d);
    writeCost(cost_, c);
    writeController(prev_, p);
    dyn_text_ = d.text();
    cost_text_ = c.text();
    prev_text_ = p.text();
    writeAll(dyn_text_, cost_text_, prev_text_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  void writeAll(const std::string& d, const std::string& c, const std::string& p) {
    writeText(path("dyn.txt"), d);
    writeText(path("cost.txt"), c);
    writeText(path("prev.txt"), p);
  }
  std::string path(const std::string& name) const { return dir_ + "/" + name; }
  std::string args(double epsilon = 0.5) const {
    return "--dynamics " + path("dyn.txt") + " --cost " + path("cost.txt") + " --controller " + path("prev.txt") +
           " --epsilon " + std::to_string(epsilon) + " --out " + path("new.txt");
  }
  static std::string replaced(std::string text, const std::string& from, const std::string& to) {
    const size_t at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) text.replace(at, from.size(), to);
    return text;
  }

  const int nx_ = 4, nu_ = 2, T_ = 6;
  std::string dir_, dyn_text_, cost_text_, prev_text_;
  LgDynamics dyn_;
  QuadraticCost cost_;
  LgController prev_;
};

}  // namespace

TEST_F(KlTool, OutputEqualsTheLibrarysUpdate) {
  const ToolRun run = runTool(args(0.5));
  ASSERT_EQ(run.status, 0) << run.output;
  const MatrixFile out = MatrixFile::read(path("new.txt"));
  const LgController tool = readController(out, nx_, nu_, T_);

  KlUpdate update(nx_, nu_, T_);
  const KlUpdateResult lib = update.update(dyn_, cost_, prev_, 0.5);
  ASSERT_TRUE(lib.converged);
  EXPECT_EQ(out.get("eta", 1, 1)(0, 0), lib.eta);  // same inputs bit for bit: same numbers
  EXPECT_EQ(out.get("kl", 1, 1)(0, 0), lib.kl);
  EXPECT_EQ(out.get("predicted_cost", 1, 1)(0, 0), lib.predicted_cost);
  EXPECT_EQ(out.get("converged", 1, 1)(0, 0), 1.0);
  for (int t = 0; t < T_; ++t) {
    EXPECT_EQ(tool.K[t], lib.controller.K[t]) << t;
    EXPECT_EQ(tool.k[t], lib.controller.k[t]) << t;
    EXPECT_EQ(tool.covariance(t), lib.controller.covariance(t)) << t;
  }
  // The output is a valid previous controller for the next update.
  writeText(path("prev.txt"), out.text());
  EXPECT_EQ(runTool(args(0.5)).status, 0);
}

TEST_F(KlTool, MissingBlockIsNamed) {
  writeAll(replaced(dyn_text_, "\nFu.2 ", "\nFu_renamed.2 "), cost_text_, prev_text_);
  const ToolRun run = runTool(args());
  EXPECT_EQ(run.status, 1);
  EXPECT_NE(run.output.find(path("dyn.txt") + ": block 'Fu.2': missing"), std::string::npos) << run.output;
}

TEST_F(KlTool, WrongShapeIsNamed) {
  writeAll(dyn_text_, replaced(cost_text_, "\ncuu.1 2 2\n", "\ncuu.1 1 4\n"), prev_text_);
  const ToolRun run = runTool(args());
  EXPECT_EQ(run.status, 1);
  EXPECT_NE(run.output.find(path("cost.txt") + ": block 'cuu.1': is 1x4, expected 2x2"), std::string::npos)
      << run.output;
}

TEST_F(KlTool, NonFiniteNumberIsNamed) {
  // The first number of k.3 becomes nan.
  const size_t head = prev_text_.find("\nk.3 2 1\n");
  ASSERT_NE(head, std::string::npos);
  const size_t first = head + std::string("\nk.3 2 1\n").size();
  std::string bad = prev_text_;
  bad.replace(first, bad.find('\n', first) - first, "nan");
  writeAll(dyn_text_, cost_text_, bad);
  const ToolRun run = runTool(args());
  EXPECT_EQ(run.status, 1);
  EXPECT_NE(run.output.find(path("prev.txt")), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("block 'k.3': entry (0, 0)"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("is not finite: 'nan'"), std::string::npos) << run.output;
}

TEST_F(KlTool, BadArgumentsAndMissingFilesFail) {
  ToolRun run = runTool("--dynamics " + path("dyn.txt"));
  EXPECT_EQ(run.status, 1);
  EXPECT_NE(run.output.find("usage: kl_update"), std::string::npos) << run.output;
  run = runTool(args(0.5) + " --epsilon -1");
  EXPECT_EQ(run.status, 1);
  EXPECT_NE(run.output.find("--epsilon needs a positive number"), std::string::npos) << run.output;
  run = runTool(replaced(args(), path("cost.txt"), path("absent.txt")));
  EXPECT_EQ(run.status, 1);
  EXPECT_NE(run.output.find(path("absent.txt") + ": cannot open"), std::string::npos) << run.output;
}

TEST_F(KlTool, OverflowIsReportedAsAFailureNotAConvergedUpdate) {
  // Finite but huge dynamics (f = 1e160): the marginals overflow. Before, the tool wrote the
  // update with a non-finite predicted cost and exit status 0.
  LgDynamics huge = dyn_;
  for (auto& f : huge.f) f.setConstant(1e160);
  MatrixFile d("dyn");
  writeDynamics(huge, d);
  writeAll(d.text(), cost_text_, prev_text_);
  const ToolRun run = runTool(args());
  EXPECT_EQ(run.status, 2) << run.output;
  EXPECT_NE(run.output.find("KL or expected cost not finite"), std::string::npos) << run.output;
  EXPECT_FALSE(std::filesystem::exists(path("new.txt")));
}

TEST_F(KlTool, IndefiniteCovariancesAreRefusedNamingTheBlock) {
  LgDynamics bad = dyn_;
  bad.Sigma[2](0, 0) = -1.0;  // symmetric, indefinite
  MatrixFile d("dyn");
  writeDynamics(bad, d);
  writeAll(d.text(), cost_text_, prev_text_);
  ToolRun run = runTool(args());
  EXPECT_EQ(run.status, 1) << run.output;
  EXPECT_NE(run.output.find(path("dyn.txt") + ": block 'Sigma.2': not positive semi-definite"), std::string::npos)
      << run.output;
  bad = dyn_;
  bad.x0_cov(1, 2) = bad.x0_cov(2, 1) = 1.0;  // off-diagonal 1 on a 0.01 diagonal
  d = MatrixFile("dyn");
  writeDynamics(bad, d);
  writeAll(d.text(), cost_text_, prev_text_);
  run = runTool(args());
  EXPECT_EQ(run.status, 1) << run.output;
  EXPECT_NE(run.output.find("block 'x0_cov': not positive semi-definite"), std::string::npos) << run.output;
}

TEST_F(KlTool, ABadHeaderNamesTheBlockNotANumber) {
  // One number too many in k.3: the surplus stands where the next header should.
  writeAll(dyn_text_, cost_text_, replaced(prev_text_, "\nk.3 2 1\n", "\nk.3 2 1\n0.5\n"));
  const ToolRun run = runTool(args());
  EXPECT_EQ(run.status, 1) << run.output;
  EXPECT_NE(run.output.find("block 'k.3' (2x1): the number"), std::string::npos) << run.output;
  EXPECT_EQ(run.output.find("block '0"), std::string::npos) << run.output;
}

TEST_F(KlTool, AFifoInputIsRefusedWithoutBlocking) {
  ASSERT_EQ(mkfifo(path("fifo").c_str(), 0600), 0);
  const ToolRun run = runTool(replaced(args(), path("dyn.txt"), path("fifo")));
  EXPECT_EQ(run.status, 1) << run.output;
  EXPECT_NE(run.output.find(path("fifo") + ": not a regular file (a FIFO)"), std::string::npos) << run.output;
}
