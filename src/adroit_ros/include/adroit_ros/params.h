// Typed access to a node's private parameters. Every error is one line that names the
// parameter by its full name ("bad parameter /adroit_sim/rate: must be in (0, 2000]"), so a
// node refuses to start with exactly what to fix (DESIGN.md §4).
#pragma once

#include <ros/node_handle.h>

#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace adroit::rosutil {

// A parameter is missing, malformed or out of range; what() is the one line to print.
class ParameterError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class Params {
 public:
  explicit Params(const ros::NodeHandle& pnh) : pnh_(pnh) {}

  std::string name(const std::string& key) const { return pnh_.resolveName(key); }
  [[noreturn]] void fail(const std::string& key, const std::string& what) const;
  bool has(const std::string& key) const { return pnh_.hasParam(key); }

  // The value if set (a wrong type throws), else the fallback. An integer is a number too.
  double number(const std::string& key, double fallback) const;
  // ... and within [lo, hi] (a fallback outside is the caller's bug, and is reported too).
  double number(const std::string& key, double fallback, double lo, double hi) const;
  int integer(const std::string& key, int fallback) const;
  int integer(const std::string& key, int fallback, int lo, int hi) const;
  bool boolean(const std::string& key, bool fallback) const;
  std::string string(const std::string& key, const std::string& fallback) const;
  std::vector<std::string> strings(const std::string& key) const;  // empty if unset

  // A misspelt key would otherwise be ignored silently and its default used: every key in
  // the map `ns` ("" = the private namespace itself) must be one of `allowed`.
  void checkKeys(const std::string& ns, const std::set<std::string>& allowed) const;

  // The MuJoCo model a node works on: ~model_file if set, else the MJCF of scene ~scene
  // (default `default_scene`) of adroit_description, its planning variant if asked.
  std::string modelPath(const std::string& default_scene, bool planning = false) const;

 private:
  ros::NodeHandle pnh_;
};

}  // namespace adroit::rosutil
