#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "adroit_core/command_line.h"

namespace {

// Parses `words` (after the program name) as a benchmark would; returns the values read.
struct Parsed {
  long long iterations = 0;
  double noise = 0;
  std::string out;
};

Parsed parse(std::vector<std::string> words) {
  words.insert(words.begin(), "tool");
  std::vector<char*> argv;
  for (auto& w : words) argv.push_back(w.data());
  adroit::CommandLine args(static_cast<int>(argv.size()), argv.data(), "usage: tool [--iterations N] [--noise X] [--out DIR]");
  Parsed p;
  while (args.next()) {
    if (args.is("--iterations")) p.iterations = args.integer();
    else if (args.is("--noise")) p.noise = args.number();
    else if (args.is("--out")) p.out = args.text();
    else args.unknown();
  }
  return p;
}

}  // namespace

TEST(CommandLine, ReadsFlagsInAnyOrder) {
  const Parsed p = parse({"--out", "dir", "--noise", "0.25", "--iterations", "12"});
  EXPECT_EQ(p.iterations, 12);
  EXPECT_DOUBLE_EQ(p.noise, 0.25);
  EXPECT_EQ(p.out, "dir");
  EXPECT_EQ(parse({}).iterations, 0);
}

TEST(CommandLine, BadInputExitsWithTheReasonAndTheUsage) {
  EXPECT_EXIT(parse({"--iterations"}), testing::ExitedWithCode(2), "--iterations needs a value\nusage: tool");
  EXPECT_EXIT(parse({"--iterations", "12x"}), testing::ExitedWithCode(2), "--iterations needs an integer, not '12x'");
  EXPECT_EXIT(parse({"--noise", "abc"}), testing::ExitedWithCode(2), "--noise needs a number, not 'abc'");
  EXPECT_EXIT(parse({"--noise", ""}), testing::ExitedWithCode(2), "needs a number");
  EXPECT_EXIT(parse({"--juggle", "3"}), testing::ExitedWithCode(2), "unknown option '--juggle'\nusage: tool");
}
