#include "robustness.h"

#include <adroit_core/mujoco_model.h>
#include <adroit_core/number_text.h>
#include <adroit_mpc/planning_model.h>
#include <adroit_mpc/task.h>
#include <adroit_mpc/task_params.h>
#include <adroit_mpc/type_task.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <stdexcept>

namespace success {

using adroit::shortNumber;

bool parseNumber(const std::string& text, double* value) {
  char* end = nullptr;
  errno = 0;
  *value = std::strtod(text.c_str(), &end);
  return !text.empty() && *end == '\0' && errno == 0 && std::isfinite(*value);
}

namespace {

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> out;
  std::stringstream in(text);
  for (std::string item; std::getline(in, item, separator);) out.push_back(item);
  return out;
}

bool has(const std::vector<std::string>& list, const std::string& item) {
  return std::find(list.begin(), list.end(), item) != list.end();
}

std::string join(const std::vector<std::string>& list) {
  std::string out;
  for (const auto& item : list) out += (out.empty() ? "" : ", ") + item;
  return out;
}

// A number in [min, max] from text; "" when good, else why.
std::string numberIn(const std::string& text, double min, double max, const char* unit, double* value) {
  if (!parseNumber(text, value)) return "needs a number, not '" + text + "'";
  if (*value < min || *value > max)
    return "must be in [" + shortNumber(min) + ", " + shortNumber(max) + "] " + unit + ", got " + text;
  return "";
}

std::string setDropHeight(World& w, const std::string& text) {
  const auto parts = split(text, ',');
  if (parts.empty() || parts.size() > 2) return "needs MIN,MAX or one height H [m], not '" + text + "'";
  double low = 0, high = 0;
  std::string why = numberIn(parts[0], 0, 0.5, "m", &low);
  if (why.empty() && parts.size() == 2) why = numberIn(parts[1], 0, 0.5, "m", &high);
  else high = low;
  if (!why.empty()) return why;
  if (low > high) return "needs MIN <= MAX, got " + text;
  w.drop_center = 0.5 * (low + high);
  w.drop_half = 0.5 * (high - low);
  return "";
}

std::string setKeySet(World& w, const std::string& text) {
  if (text.empty()) return "needs at least one digit";
  for (char c : text)
    if (c < '0' || c > '9') return "takes digits only (the keypad's 0-9), not '" + text + "'";
  std::string sorted = text;
  std::sort(sorted.begin(), sorted.end());
  if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) return "names a digit twice: '" + text + "'";
  w.key_set = text;
  return "";
}

}  // namespace

const std::vector<std::string>& worldOptionNames() {
  static const std::vector<std::string> names = {"object_mass",  "object_scale", "drop_height", "drop_offset",
                                                 "sensor_noise", "keys",         "key_set"};
  return names;
}

std::string setWorldOption(World& w, const std::string& name, const std::string& text) {
  double x = 0;
  std::string why;
  if (name == "object_mass") {
    if ((why = numberIn(text, 1e-3, 10, "kg", &x)).empty()) w.object_mass = x;
  } else if (name == "object_scale") {
    if ((why = numberIn(text, 0.25, 4, "(size factor)", &x)).empty()) w.object_scale = x;
  } else if (name == "drop_height") {
    why = setDropHeight(w, text);
  } else if (name == "drop_offset") {
    if ((why = numberIn(text, 0, 0.1, "m", &x)).empty()) w.drop_offset = x;
  } else if (name == "sensor_noise") {
    if ((why = numberIn(text, 0, 100, "(factor)", &x)).empty()) w.sensor_noise = x;
  } else if (name == "keys") {
    why = numberIn(text, 1, adroit_mpc::TypeTask::kMaxSequence, "keys", &x);
    if (why.empty() && x != std::floor(x)) why = "needs a whole number of keys, got " + text;
    if (why.empty()) w.keys = static_cast<int>(x);
  } else if (name == "key_set") {
    why = setKeySet(w, text);
  } else {
    why = "unknown option '" + name + "' (known: " + join(worldOptionNames()) + ")";
  }
  return why;
}

std::vector<std::string> changedOptions(const World& w) {
  const World tuned;
  std::vector<std::string> out;
  if (w.object_mass != tuned.object_mass) out.push_back("object_mass");
  if (w.object_scale != tuned.object_scale) out.push_back("object_scale");
  if (w.drop_center != tuned.drop_center || w.drop_half != tuned.drop_half) out.push_back("drop_height");
  if (w.drop_offset != tuned.drop_offset) out.push_back("drop_offset");
  if (w.sensor_noise != tuned.sensor_noise) out.push_back("sensor_noise");
  if (w.keys != tuned.keys) out.push_back("keys");
  if (w.key_set != tuned.key_set) out.push_back("key_set");
  return out;
}

std::string whyNoEffect(const std::string& name, const std::vector<std::string>& tasks, bool sensed,
                        bool pneumatic_variant) {
  const bool object_option = name.rfind("object_", 0) == 0 || name.rfind("drop_", 0) == 0;
  if (object_option && !has(tasks, "catch") && !has(tasks, "relocate"))
    return "only catch and relocate drop an object (tasks: " + join(tasks) + ")";
  if ((name == "keys" || name == "key_set") && !has(tasks, "type"))
    return "only task type types keys (tasks: " + join(tasks) + ")";
  if (name == "sensor_noise" && !sensed && !pneumatic_variant)
    return "nothing reads the sensors: the planner sees the true state (add --sensed) and no variant runs the "
           "pools, which read the sensed pressures";
  return "";
}

std::string describe(const World& w) {
  std::vector<std::string> parts;
  for (const auto& name : changedOptions(w)) {
    if (name == "object_mass") parts.push_back("object mass " + shortNumber(w.object_mass) + " kg");
    if (name == "object_scale") parts.push_back("object size x" + shortNumber(w.object_scale));
    if (name == "drop_height")
      parts.push_back("dropped " + shortNumber(100 * (w.drop_center - w.drop_half)) + "-" +
                      shortNumber(100 * (w.drop_center + w.drop_half)) + " cm above the goal / hold");
    if (name == "drop_offset") parts.push_back("sideways +-" + shortNumber(100 * w.drop_offset) + " cm");
    if (name == "sensor_noise") parts.push_back("sensor noise x" + shortNumber(w.sensor_noise));
    if (name == "keys") parts.push_back(std::to_string(w.keys) + " keys a sequence");
    if (name == "key_set") parts.push_back("keys from " + w.key_set);
  }
  return join(parts);
}

void scaleSensorNoise(double factor, adroit::driver::SensorRealism& s) {
  if (factor == 1) return;
  for (double* noise : {&s.joint_noise_std, &s.joint_velocity_noise_std, &s.slide_noise_std,
                      &s.slide_velocity_noise_std, &s.touch_noise_std, &s.object_noise_std,
                      &s.cylinder.pressure_noise_std, &s.cylinder.length_noise_std})
    *noise *= factor;
}

ObjectVariantScene::ObjectVariantScene(const std::string& scene_file, double mass, double scale) {
  adroit::ModelPtr model = adroit::loadModelFile(scene_file).model;
  if (!adroit_mpc::scaleObjectBody(model.get(), mass, scale))
    throw std::invalid_argument("scene '" + scene_file + "' has no body 'object' to change");
  static std::atomic<int> count{0};
  path_ = (std::filesystem::temp_directory_path() /
           ("mpc_success_" + std::to_string(::getpid()) + "_" + std::to_string(count++) + ".mjb"))
              .string();
  mj_saveModel(model.get(), path_.c_str(), nullptr, 0);
}

ObjectVariantScene::~ObjectVariantScene() {
  std::error_code ignored;
  std::filesystem::remove(path_, ignored);
}

std::string parseSweep(const std::string& text, Sweep* out) {
  const auto equals = text.find('=');
  if (equals == std::string::npos) return "needs NAME=v1,v2,... (names: " + join(worldOptionNames()) + ")";
  Sweep sweep{text.substr(0, equals), split(text.substr(equals + 1), ',')};
  if (!has(worldOptionNames(), sweep.name))
    return "cannot sweep '" + sweep.name + "' (names: " + join(worldOptionNames()) + ")";
  if (sweep.values.empty()) return sweep.name + " needs at least one value";
  for (const auto& value : sweep.values) {
    World scratch;
    const std::string why = setWorldOption(scratch, sweep.name, value);
    if (!why.empty()) return sweep.name + "=" + value + ": " + why;
  }
  *out = sweep;
  return "";
}

namespace {

// Task numbers mpc_success takes from its own flags, or that no task reads: --set would be
// accepted by the task and change nothing.
const std::map<std::string, std::string>& refusedKeys() {
  static const std::map<std::string, std::string> refused = {
      {"horizon", "the benchmark plans over --horizon S (default: the task's hint), not this key"},
      {"planner_dt", "the benchmark plans at --dt S (default: the task's hint), not this key"},
      {"derivative_skip", "the benchmark takes --skip K (default: the task's hint), not this key"},
      {"feedback_scale", "the benchmark takes --feedback-scale F (default: the task's hint), not this key"},
      {"latency_compensation", "the benchmark takes --compensation on|off|task, not this key"},
      {"object_mass", "no task reads it; the object's mass in both worlds is --object-mass KG"},
      {"object_radius", "no task reads it; the object's size in both worlds is --object-scale S"}};
  return refused;
}

std::string knownKeys(const std::string& task) {
  std::vector<std::string> keys;
  for (const auto& [key, value] : adroit_mpc::defaultTaskParams(task).numbers)
    if (!refusedKeys().count(key)) keys.push_back(key);
  return join(keys);
}

// One --set text into out; "" when good.
std::string addTaskParam(const std::string& text, const std::vector<std::string>& tasks, TaskNumbers& out) {
  const auto equals = text.find('=');
  double value = 0;
  if (equals == std::string::npos || !parseNumber(text.substr(equals + 1), &value))
    return "--set needs [task.]key=number, not '" + text + "'";
  std::string key = text.substr(0, equals);
  std::vector<std::string> targets = tasks;
  if (const auto dot = key.find('.'); dot != std::string::npos) {
    const std::string task = key.substr(0, dot);
    if (!has(tasks, task)) return "--set " + key + ": task '" + task + "' does not run (tasks: " + join(tasks) + ")";
    targets = {task};
    key = key.substr(dot + 1);
  }
  if (refusedKeys().count(key)) return "--set " + key + ": " + refusedKeys().at(key);
  for (const auto& task : targets) {
    if (!adroit_mpc::defaultTaskParams(task).numbers.count(key))
      return "--set " + key + ": task " + task + " has no number parameter '" + key + "' (known: " + knownKeys(task) +
             (targets.size() > 1 ? "; scope a key to one task as <task>." + key : "") + ")";
    out[task][key] = value;
  }
  return "";
}

}  // namespace

std::string resolveTaskParams(const std::vector<std::string>& sets, const std::vector<std::string>& tasks,
                              TaskNumbers* out) {
  TaskNumbers params;
  for (const auto& text : sets)
    if (const std::string why = addTaskParam(text, tasks, params); !why.empty()) return why;
  for (const auto& [task, numbers] : params) {  // ranges: the task refuses what it cannot take
    adroit_mpc::TaskParams given;
    given.numbers = numbers;
    try {
      adroit_mpc::makeTask(task, given);
    } catch (const std::invalid_argument& e) {
      return std::string("--set: ") + e.what();
    }
  }
  *out = params;
  return "";
}

}  // namespace success
