#include "adroit_core/run_program.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>

namespace {

using adroit::runProgram;

adroit::ProgramOptions options(double timeout_s, bool capture = false, size_t max_output = 1 << 20) {
  adroit::ProgramOptions o;
  o.timeout_s = timeout_s;
  o.capture_output = capture;
  o.max_output = max_output;
  return o;
}

TEST(RunProgram, PassesEachArgumentAsItIsWithoutAShell) {
  const std::string marker = "/tmp/adroit_run_program_" + std::to_string(getpid());
  std::filesystem::remove(marker);
  // What a hostile output_dir would be in a shell command line: here only text for echo.
  const std::string hostile = "q'; touch " + marker + "; echo '";
  const auto r = runProgram({"echo", hostile, "$(id)"}, options(10, true));
  ASSERT_TRUE(r.ok()) << r.describe();
  EXPECT_EQ(r.output, hostile + " $(id)\n");
  EXPECT_FALSE(std::filesystem::exists(marker));
}

TEST(RunProgram, ReportsTheExitCode) {
  const auto r = runProgram({"sh", "-c", "exit 3"}, options(10));
  EXPECT_TRUE(r.started);
  EXPECT_FALSE(r.ok());
  EXPECT_EQ(r.exit_code, 3);
  EXPECT_EQ(r.describe(), "exit 3");
}

TEST(RunProgram, AMissingProgramIsAnErrorNotACrash) {
  const auto r = runProgram({"adroit-no-such-program", "x"});
  EXPECT_FALSE(r.started);
  EXPECT_FALSE(r.ok());
  EXPECT_NE(r.describe().find("cannot start 'adroit-no-such-program'"), std::string::npos) << r.describe();
  EXPECT_FALSE(runProgram({}).ok());
}

TEST(RunProgram, KillsAProgramPastItsTimeoutWithItsChildren) {
  const auto start = std::chrono::steady_clock::now();
  // The shell's child sleep holds the output pipe: killing only the shell would leave the
  // reader waiting for the sleep.
  const auto r = runProgram({"sh", "-c", "sleep 30; echo late"}, options(0.3, true));
  const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_TRUE(r.timed_out);
  EXPECT_FALSE(r.ok());
  EXPECT_EQ(r.output, "");
  EXPECT_LT(took, 10.0);
}

TEST(RunProgram, KeepsOutputUpToItsLimitAndReadsTheRest) {
  const auto r = runProgram({"head", "-c", "1000000", "/dev/zero"},
                            options(20, true, 100));
  ASSERT_TRUE(r.ok()) << r.describe();  // not blocked on a full pipe
  EXPECT_EQ(r.output.size(), 100u);
}

TEST(RunProgram, CapturesStandardErrorOnlyWhenAsked) {
  auto o = options(10, true);
  EXPECT_EQ(runProgram({"sh", "-c", "echo out; echo err >&2"}, o).output, "out\n");
  o.merge_stderr = true;
  EXPECT_EQ(runProgram({"sh", "-c", "echo out; echo err >&2"}, o).output, "out\nerr\n");
}

TEST(RunProgram, GivesTheProgramNoStandardInput) {
  const auto r = runProgram({"cat"}, options(10, true));
  ASSERT_TRUE(r.ok()) << r.describe();
  EXPECT_EQ(r.output, "");
}

}  // namespace
