#include "pool_params.h"

#include <algorithm>
#include <cctype>
#include <map>
#include <set>

#include <ros/names.h>
#include <ros/package.h>
#include <ros/time.h>

#include "adroit_pneumatics/params_io.h"
#include "adroit_ros/params.h"

namespace adroit::pneumatics {

namespace {

using rosutil::Params;

// What a pool's namespace may set (a group member's inherits the group's when it does not).
const std::set<std::string> kPoolKeys = {"model_file",  "scene",           "cylinders",       "pool",
                                         "group_size",  "controller",      "params_file",     "reference_timeout",
                                         "state_timeout", "stamp_tolerance", "exhaust_volts", "ilqg", "pidf"};
// The threads' settings: one value per node, shared by the pools of a group.
const std::set<std::string> kThreadKeys = {"rate", "diagnostics_period", "realtime_priority", "tick_phase",
                                           "tick_on_state"};

void checkAllKeys(const Params& p, const std::set<std::string>& allowed) {
  p.checkKeys("", allowed);
  p.checkKeys("ilqg", {"horizon", "dt", "alpha_p", "alpha_u", "alpha_w", "u_min", "u_max", "iterations",
                       "feedback_fraction", "solve_every", "solve_budget", "disturbance_gain", "disturbance_limit",
                       "u_des_steady_state", "measurement_gain", "measurement_band", "jump_threshold",
                       "jump_iterations"});
  p.checkKeys("pidf", {"kp", "ki", "kd", "filter_hz", "feedforward", "feedforward_advance", "u_min", "u_max"});
}

// The controller options set in `ns`, each unset one from `o` (the defaults, or the group's).
PoolOptions readOptions(const Params& p, const ros::NodeHandle& ns, PoolOptions o) {
  o.controller = p.string("controller", o.controller);
  o.reference_timeout = p.number("reference_timeout", o.reference_timeout);
  o.state_timeout = p.number("state_timeout", o.state_timeout);
  o.stamp_tolerance = p.number("stamp_tolerance", o.stamp_tolerance);
  o.exhaust_volts = p.number("exhaust_volts", o.exhaust_volts);
  o.ilqg.horizon = p.integer("ilqg/horizon", o.ilqg.horizon);
  o.ilqg.dt = p.number("ilqg/dt", o.ilqg.dt);
  o.ilqg.alpha_p = p.number("ilqg/alpha_p", o.ilqg.alpha_p);
  o.ilqg.alpha_u = p.number("ilqg/alpha_u", o.ilqg.alpha_u);
  o.ilqg.alpha_w = p.number("ilqg/alpha_w", o.ilqg.alpha_w);
  o.ilqg.u_min = p.number("ilqg/u_min", o.ilqg.u_min);
  o.ilqg.u_max = p.number("ilqg/u_max", o.ilqg.u_max);
  o.ilqg.iterations = p.integer("ilqg/iterations", o.ilqg.iterations);
  o.ilqg.feedback_fraction = p.number("ilqg/feedback_fraction", o.ilqg.feedback_fraction);
  o.solve_every = p.integer("ilqg/solve_every", o.solve_every);
  o.solve_budget = p.number("ilqg/solve_budget", o.solve_budget);
  o.ilqg.disturbance_gain = p.number("ilqg/disturbance_gain", o.ilqg.disturbance_gain);
  o.ilqg.disturbance_limit = p.number("ilqg/disturbance_limit", o.ilqg.disturbance_limit);
  o.ilqg.u_des_steady_state = p.boolean("ilqg/u_des_steady_state", o.ilqg.u_des_steady_state);
  o.ilqg.measurement_gain = p.number("ilqg/measurement_gain", o.ilqg.measurement_gain);
  o.ilqg.measurement_band = p.number("ilqg/measurement_band", o.ilqg.measurement_band);
  o.ilqg.jump_threshold = p.number("ilqg/jump_threshold", o.ilqg.jump_threshold);
  o.ilqg.jump_iterations = p.integer("ilqg/jump_iterations", o.ilqg.jump_iterations);
  o.pidf.kp = p.number("pidf/kp", o.pidf.kp);
  o.pidf.ki = p.number("pidf/ki", o.pidf.ki);
  o.pidf.kd = p.number("pidf/kd", o.pidf.kd);
  o.pidf.filter_hz = p.number("pidf/filter_hz", o.pidf.filter_hz);
  o.pidf.feedforward = p.boolean("pidf/feedforward", o.pidf.feedforward);
  o.pidf.feedforward_advance = p.number("pidf/feedforward_advance", o.pidf.feedforward_advance);
  o.pidf.u_min = p.number("pidf/u_min", o.pidf.u_min);
  o.pidf.u_max = p.number("pidf/u_max", o.pidf.u_max);
  try {
    o.validate();
  } catch (const std::exception& e) {
    // The options' messages start with the field ("ilqg: horizon ...", "controller: ...").
    throw rosutil::ParameterError("bad parameter " + ns.getNamespace() + "/" + e.what());
  }
  return o;
}

// A pool's settings apart from its cylinders: the model and parametric models are loaded
// where they are set (once for a group whose members inherit them).
struct Settings {
  std::string model_file;
  std::vector<description::Cylinder> table;  // the model's cylinders, model order
  std::string params_file;
  ParameterSet models;
  int group_size = 8;
  PoolOptions options;
};

Settings readSettings(const Params& p, const ros::NodeHandle& ns, const Settings* inherited) {
  Settings s = inherited ? *inherited : Settings{};
  if (!inherited || p.has("model_file") || p.has("scene")) {
    s.model_file = p.modelPath("arm_hand");
    try {
      s.table = loadModelCylinders(s.model_file);
    } catch (const std::exception& e) {
      p.fail(p.has("model_file") ? "model_file" : "scene", e.what());
    }
  }
  if (!inherited || p.has("params_file")) {
    // A malformed YAML names its field (params_io).
    s.params_file =
        p.string("params_file", ros::package::getPath("adroit_pneumatics") + "/config/parametric_default.yaml");
    try {
      s.models = loadParameterSet(s.params_file);
    } catch (const std::exception& e) {
      p.fail("params_file", e.what());
    }
  }
  for (const auto& kv : s.models.cylinders) {
    const bool known = std::any_of(s.table.begin(), s.table.end(), [&](const auto& c) { return c.name == kv.first; });
    if (!known)
      p.fail("params_file", s.params_file + ": parametric.cylinders." + kv.first + ": not a cylinder of " + s.model_file);
  }
  s.group_size = p.integer("group_size", s.group_size, 1, 1000);
  s.options = readOptions(p, ns, s.options);
  return s;
}

// The pool's cylinders (~cylinders, or ~pool into the default split). `owner` (cylinder ->
// pool label) refuses a cylinder named twice, in this pool or in another of the group: the
// group's command names each cylinder once, and the driver rejects one that does not, whole.
PoolSpec readPool(const Params& p, const Settings& s, const std::string& name, const std::string& label,
                  std::map<std::string, std::string>* owner) {
  PoolSpec spec;
  spec.name = name;
  spec.options = s.options;
  for (const auto& c : s.table) spec.known.push_back(c.name);
  std::vector<std::string> mine = p.strings("cylinders");
  const char* key = "cylinders";
  if (mine.empty()) {
    if (!p.has("pool")) p.fail("cylinders", "set ~cylinders (list of names) or ~pool (index into the default split)");
    const auto split = defaultPoolSplit(spec.known, s.group_size);
    key = "pool";
    mine = split[p.integer("pool", 0, 0, static_cast<int>(split.size()) - 1)];
  } else if (p.has("pool")) {
    p.fail("pool", "give either ~cylinders or ~pool, not both");
  }
  for (const auto& n : mine) {
    const auto it = std::find_if(s.table.begin(), s.table.end(), [&](const auto& c) { return c.name == n; });
    if (it == s.table.end()) p.fail("cylinders", "unknown cylinder '" + n + "' (not in " + s.model_file + ")");
    const auto [first, fresh] = owner->emplace(n, label);
    if (!fresh && first->second == label) p.fail(key, "cylinder '" + n + "' listed twice");
    if (!fresh) p.fail(key, "cylinder '" + n + "' is also in member '" + first->second + "' of this group");
    spec.cylinders.push_back({n, it->bore_area, deadVolume(it->type, it->bore_diameter), s.models.forCylinder(n)});
  }
  return spec;
}

void checkMembers(const Params& p, const std::vector<std::string>& members) {
  std::set<std::string> seen;
  for (const auto& m : members) {
    const auto plain = [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; };
    const bool valid =
        !m.empty() && std::isalpha(static_cast<unsigned char>(m[0])) && std::all_of(m.begin(), m.end(), plain);
    if (!valid) p.fail("members", "'" + m + "' is not a plain name (letters, digits, _)");
    if (!seen.insert(m).second) p.fail("members", "'" + m + "' listed twice");
    if (kPoolKeys.count(m) || kThreadKeys.count(m) || m == "members")
      p.fail("members", "'" + m + "' is a parameter name; call the member otherwise");
  }
}

}  // namespace

GroupSpec readGroupSpec(const ros::NodeHandle& pnh, const std::string& node_name) {
  const Params p(pnh);
  const std::vector<std::string> members = p.strings("members");
  checkMembers(p, members);
  std::set<std::string> allowed = kPoolKeys;
  allowed.insert(kThreadKeys.begin(), kThreadKeys.end());
  allowed.insert("members");
  allowed.insert(members.begin(), members.end());
  checkAllKeys(p, allowed);

  GroupSpec g;
  g.rate = p.number("rate", g.rate, 1e-3, 2000.0);
  g.diagnostics_period = p.number("diagnostics_period", g.diagnostics_period, 1e-3, 3600.0);
  g.realtime_priority = p.integer("realtime_priority", g.realtime_priority, 0, 98);
  g.tick_phase = p.number("tick_phase", g.tick_phase, 0.0, 0.999999);
  g.tick_on_state = p.boolean("tick_on_state", g.tick_on_state);
  if (g.tick_on_state && ros::Time::isSimTime())
    p.fail("tick_on_state", "true needs wall time (a driver whose samples arrive on their own: the hardware)");

  const Settings shared = readSettings(p, pnh, nullptr);
  std::map<std::string, std::string> owner;
  if (members.empty()) {
    g.pools.push_back(readPool(p, shared, node_name, node_name, &owner));
    return g;
  }
  for (const char* key : {"cylinders", "pool"})
    if (p.has(key)) p.fail(key, "with ~members each member names its own (~<member>/cylinders or ~<member>/pool)");
  const std::string ns = ros::names::parentNamespace(pnh.getNamespace());
  for (const auto& m : members) {
    const ros::NodeHandle mh(pnh, m);
    const Params mp(mh);
    for (const auto& key : kThreadKeys)
      if (mp.has(key)) mp.fail(key, "one value for the whole group: set " + p.name(key));
    checkAllKeys(mp, kPoolKeys);
    g.pools.push_back(readPool(mp, readSettings(mp, mh, &shared), ros::names::append(ns, m), m, &owner));
  }
  return g;
}

}  // namespace adroit::pneumatics
