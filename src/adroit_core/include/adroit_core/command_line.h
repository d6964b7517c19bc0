// "--flag value" options of the command-line tools and benchmarks. A flag without its value, a
// number that does not parse completely, or an unknown flag prints what is wrong and the usage
// line to stderr and exits with status 2, so a typo never runs a long benchmark with a default.
//
//   adroit::CommandLine args(argc, argv, "usage: tool [--iterations N] [--out DIR]");
//   while (args.next()) {
//     if (args.is("--iterations")) iterations = args.integer();
//     else if (args.is("--out")) out = args.text();
//     else args.unknown();
//   }
#pragma once
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace adroit {

class CommandLine {
 public:
  CommandLine(int argc, char** argv, std::string usage) : argc_(argc), argv_(argv), usage_(std::move(usage)) {}

  // Moves to the next flag; false after the last argument.
  bool next() {
    if (index_ >= argc_) return false;
    flag_ = argv_[index_++];
    return true;
  }
  bool is(const char* name) const { return flag_ == name; }
  const std::string& flag() const { return flag_; }

  // The current flag's value.
  std::string text() {
    if (index_ >= argc_) fail(flag_ + " needs a value");
    return argv_[index_++];
  }
  double number() {
    const std::string v = text();
    char* end = nullptr;
    errno = 0;
    const double x = std::strtod(v.c_str(), &end);
    if (v.empty() || *end != '\0' || errno != 0) fail(flag_ + " needs a number, not '" + v + "'");
    return x;
  }
  long long integer() {
    const std::string v = text();
    char* end = nullptr;
    errno = 0;
    const long long x = std::strtoll(v.c_str(), &end, 10);
    if (v.empty() || *end != '\0' || errno != 0) fail(flag_ + " needs an integer, not '" + v + "'");
    return x;
  }

  [[noreturn]] void unknown() const { fail("unknown option '" + flag_ + "'"); }
  [[noreturn]] void fail(const std::string& why) const {
    std::fprintf(stderr, "%s\n%s\n", why.c_str(), usage_.c_str());
    std::exit(2);
  }

 private:
  int argc_, index_ = 1;
  char** argv_;
  std::string usage_, flag_;
};

}  // namespace adroit
