#include "options.h"

#include <adroit_core/command_line.h>

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace pneumatics = adroit::pneumatics;

namespace success {

namespace {

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream in(s);
  std::string item;
  while (std::getline(in, item, ',')) if (!item.empty()) out.push_back(item);
  return out;
}

constexpr const char* kUsage =
    "usage: mpc_success [--trials N] [--tasks catch,relocate,type] "
    "[--variants ilqg,sampling,cem,cem_pneumatic,nosyn,pneumatic,pneumatic_open,as_planned,nocomp,coldfd,fullfd,pneumatic_fullfd] [--out DIR] "
    "[--seed S] [--only-trial K] [--fixed-latency S] [--latency-sweep S,S,...] [--dt S] [--horizon S] [--skip K] "
    "[--tension-step-weight W] [--sensed] [--feedback-scale F] [--compensation on|off|task] [--contact M,S] [--events] [--idle S] "
    "[--set [task.]key=number]... [--pool ilqg_key=number]... [--object-mass KG] [--object-scale S] "
    "[--drop-height MIN,MAX] [--drop-offset M] [--sensor-noise F] [--keys N] [--key-set DIGITS] "
    "[--sweep NAME=v1,v2,...]...";

// A "--flag key=number" value; fails naming the flag.
std::pair<std::string, double> keyNumber(adroit::CommandLine& args) {
  const std::string text = args.text();
  const auto equals = text.find('=');
  double value = 0;
  if (equals == std::string::npos || !success::parseNumber(text.substr(equals + 1), &value))
    args.fail(args.flag() + " needs key=number, not '" + text + "'");
  return {text.substr(0, equals), value};
}

// "--object-mass" for the option object_mass.
std::string flagOf(std::string name) {
  std::replace(name.begin(), name.end(), '_', '-');
  return "--" + name;
}

// Variants and tasks by name, --set against the tasks, and options that would change nothing.
void checkOptions(Options& o, adroit::CommandLine& args, const std::string& tasks, const std::string& variants,
                  const std::vector<std::string>& sets) {
  if (o.trials < 1) args.fail("--trials must be at least 1");
  if (o.only_trial >= o.trials)
    args.fail("--only-trial " + std::to_string(o.only_trial) + " needs --trials > " + std::to_string(o.only_trial));
  if (!(o.overrides.tension_step_weight >= 0) || !std::isfinite(o.overrides.tension_step_weight))
    args.fail("--tension-step-weight must be >= 0 and finite");
  if (o.compensation != "task" && o.compensation != "on" && o.compensation != "off")
    args.fail("--compensation must be on, off or task (the task's hint)");
  if (o.feedback_scale != -1 && !(o.feedback_scale >= 0 && o.feedback_scale <= 1))
    args.fail("--feedback-scale must be in [0, 1]");
  for (const auto& v : split(variants)) {
    if (!knownVariants().count(v))
      args.fail("unknown variant '" + v + "' (known: ilqg, sampling, cem, cem_pneumatic, nosyn, pneumatic, "
                "pneumatic_open, as_planned, nocomp, coldfd, fullfd, pneumatic_fullfd)");
    o.variants.push_back(knownVariants().at(v));
  }
  o.tasks = split(tasks);
  for (const auto& t : o.tasks)
    if (t != "catch" && t != "relocate" && t != "type") args.fail("unknown task '" + t + "' (known: catch, relocate, type)");
  if (const std::string why = success::resolveTaskParams(sets, o.tasks, &o.params); !why.empty()) args.fail(why);
  for (const auto& name : success::changedOptions(o.world))
    if (const auto why = success::whyNoEffect(name, o.tasks, o.sensed, o.poolsRun()); !why.empty())
      args.fail(flagOf(name) + " would change nothing: " + why);
  for (const auto& sweep : o.sweeps)
    if (const auto why = success::whyNoEffect(sweep.name, o.tasks, o.sensed, o.poolsRun()); !why.empty())
      args.fail("--sweep " + sweep.name + " would change nothing: " + why);
  if (o.pool_set && !o.poolsRun()) args.fail("--pool would change nothing: no variant runs the pools");
  if (o.idle > 0 && std::find(o.tasks.begin(), o.tasks.end(), "type") == o.tasks.end())
    args.fail("--idle would change nothing: only task type rests over its keys first");
  if (!o.sweeps.empty() && !o.latency_sweep.empty())
    args.fail("--sweep and --latency-sweep: one sweep a run");
}

}  // namespace

Options parseOptions(int argc, char** argv) {
  Options o;
  o.pool_ilqg.iterations = 1;  // the pools' settings as config/pools.yaml has them
  o.overrides.horizon = o.overrides.dt = -1;
  o.overrides.derivative_skip = -1;
  std::string tasks = "catch,relocate,type", variants = "ilqg,sampling,nosyn,pneumatic";
  std::vector<std::string> sets;
  adroit::CommandLine args(argc, argv, kUsage);
  const auto world_option = [&](const char* name) {
    if (const std::string why = success::setWorldOption(o.world, name, args.text()); !why.empty())
      args.fail(args.flag() + " " + why);
  };
  while (args.next()) {
    if (args.is("--trials")) o.trials = static_cast<int>(args.integer());
    else if (args.is("--tasks")) tasks = args.text();
    else if (args.is("--variants")) variants = args.text();
    else if (args.is("--out")) o.out_dir = args.text();
    else if (args.is("--seed")) o.seed = static_cast<unsigned>(args.integer());
    else if (args.is("--only-trial")) o.only_trial = static_cast<int>(args.integer());
    else if (args.is("--fixed-latency")) o.fixed_latency = args.number();
    else if (args.is("--latency-sweep")) {
      o.latency_sweep = split(args.text());
      double latency = 0;
      for (const auto& value : o.latency_sweep)
        if (!success::parseNumber(value, &latency) || latency < 0)
          args.fail("--latency-sweep needs latencies >= 0 [s], not '" + value + "'");
    }
    else if (args.is("--sensed")) o.sensed = true;
    else if (args.is("--feedback-scale")) o.feedback_scale = args.number();
    else if (args.is("--compensation")) o.compensation = args.text();
    else if (args.is("--contact")) {
      const auto parts = split(args.text());
      if (parts.size() != 2 || !success::parseNumber(parts[0], &o.contact_margin) ||
          !success::parseNumber(parts[1], &o.contact_softness))
        args.fail("--contact needs MARGIN,SOFTNESS [m]");
    }
    else if (args.is("--dt")) o.overrides.dt = args.number();
    else if (args.is("--horizon")) o.overrides.horizon = args.number();
    else if (args.is("--skip")) o.overrides.derivative_skip = static_cast<int>(args.integer());
    else if (args.is("--tension-step-weight")) o.overrides.tension_step_weight = args.number();
    else if (args.is("--events")) o.print_events = true;
    else if (args.is("--idle")) o.idle = args.number();
    else if (args.is("--set")) sets.push_back(args.text());
    else if (args.is("--pool")) {
      const auto [key, value] = keyNumber(args);
      if (!pneumatics::setIlqgParam(o.pool_ilqg, key, value)) args.fail("--pool: unknown iLQG parameter '" + key + "'");
      o.pool_set = true;
    }
    else if (args.is("--object-mass")) world_option("object_mass");
    else if (args.is("--object-scale")) world_option("object_scale");
    else if (args.is("--drop-height")) world_option("drop_height");
    else if (args.is("--drop-offset")) world_option("drop_offset");
    else if (args.is("--sensor-noise")) world_option("sensor_noise");
    else if (args.is("--keys")) world_option("keys");
    else if (args.is("--key-set")) world_option("key_set");
    else if (args.is("--sweep")) {
      success::Sweep sweep;
      if (const std::string why = success::parseSweep(args.text(), &sweep); !why.empty()) args.fail("--sweep " + why);
      o.sweeps.push_back(sweep);
    }
    else args.unknown();
  }
  checkOptions(o, args, tasks, variants, sets);
  return o;
}

}  // namespace success
