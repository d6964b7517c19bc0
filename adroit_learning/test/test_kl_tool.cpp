// The kl_update tool (run as a process): its output equals the library's update on the same
// inputs, and bad input files end it with a non-zero status and a message naming the file,
// the block and the problem.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>

#include "adroit_learning/kl_update.h"
#include "adroit_learning/matrix_file.h"
#include "lq_problems.h"

using namespace adroit;

namespace {

struct ToolRun {
  int status;
  std::string output;  // stdout and stderr
};

ToolRun runTool(const std::string& args) {
  const std::string command = std::string(KL_UPDATE_BINARY) + " " + args + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return {-1, "popen failed"};
  std::string output;
  char buf[512];
  while (fgets(buf, sizeof buf, pipe)) output += buf;
  const int status = pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, output};
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
  void TearDown() override { std::system(("rm -rf " + dir_).c_str()); }

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
