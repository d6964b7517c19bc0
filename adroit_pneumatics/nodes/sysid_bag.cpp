// pneumatic_sysid_bag: turns a rosbag of /adroit/actuator_states and /adroit/valve_command
// (e.g. recorded while excitation_node ran) into the identification CSV of one cylinder
// (sysid.h Recording: t,volts,pressure,volume,volume_rate,supply), which pneumatic_sysid fits.
//   pneumatic_sysid_bag --bag run.bag --cylinder A_FFJ2_flex --out sweep.csv
//                       [--model scene.xml | --scene arm_hand] [--dt 0.005]
// Samples are on a uniform grid of --dt from the first state: pressure, length and rate
// interpolated linearly between state messages, the command held from the last valve
// command at or before the sample (header stamps; the bag time when a stamp is zero).
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <map>
#include <string>
#include <vector>

#include <ros/package.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>

#include <adroit_msgs/ActuatorStates.h>
#include <adroit_msgs/ValveCommand.h>

#include "adroit_core/bounded_file.h"
#include "adroit_description/scenes.h"
#include "adroit_pneumatics/pool.h"
#include "adroit_pneumatics/sysid.h"

using namespace adroit::pneumatics;

namespace {

struct Sample {
  double t, pressure, length, rate, supply;
};

double stampOf(const ros::Time& header, const ros::Time& bag) { return (header.isZero() ? bag : header).toSec(); }

}  // namespace

int main(int argc, char** argv) {
  std::string bag_path, cylinder, out, model_file, scene = "arm_hand";
  double dt = 0.005;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) {
      std::fprintf(stderr, "pneumatic_sysid_bag: %s needs a value\n", a.c_str());
      return 2;
    }
    const std::string v = argv[++i];
    if (a == "--bag") bag_path = v;
    else if (a == "--cylinder") cylinder = v;
    else if (a == "--out") out = v;
    else if (a == "--model") model_file = v;
    else if (a == "--scene") scene = v;
    else if (a == "--dt") dt = std::atof(v.c_str());
    else {
      std::fprintf(stderr, "pneumatic_sysid_bag: unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  if (bag_path.empty() || cylinder.empty() || out.empty() || !(dt > 0)) {
    std::fprintf(stderr,
                 "usage: pneumatic_sysid_bag --bag run.bag --cylinder NAME --out rec.csv [--model f.xml | --scene "
                 "arm_hand] [--dt 0.005]\n");
    return 2;
  }
  try {
    if (model_file.empty())
      model_file = adroit::description::sceneFile(ros::package::getPath("adroit_description"), scene);
    const auto table = loadModelCylinders(model_file);
    const auto me = std::find_if(table.begin(), table.end(), [&](const auto& c) { return c.name == cylinder; });
    if (me == table.end()) throw std::runtime_error("--cylinder: unknown cylinder '" + cylinder + "' in " + model_file);
    const int my_index = static_cast<int>(me - table.begin());
    const double dead = deadVolume(me->type, me->bore_diameter);

    // A FIFO would block rosbag's open for good; a bag of a day's recording is far below this.
    adroit::requireRegularFile(bag_path, 64 * adroit::kGiB);
    rosbag::Bag bag(bag_path, rosbag::bagmode::Read);
    rosbag::View view(bag, rosbag::TopicQuery(std::vector<std::string>{"/adroit/actuator_states", "/adroit/valve_command"}));
    std::vector<Sample> states;
    std::map<double, double> commands;  // time -> volts
    std::size_t skipped = 0;
    for (const rosbag::MessageInstance& m : view) {
      if (auto s = m.instantiate<adroit_msgs::ActuatorStates>()) {
        std::size_t j = 0;
        if (s->name.empty()) j = my_index;
        else j = std::find(s->name.begin(), s->name.end(), cylinder) - s->name.begin();
        const std::size_t n = s->name.empty() ? table.size() : s->name.size();
        if (j >= n || s->pressure.size() != n || s->length.size() != n || s->length_rate.size() != n ||
            !std::isfinite(s->pressure[j]) || !std::isfinite(s->length[j]) || !std::isfinite(s->length_rate[j]) ||
            !std::isfinite(s->supply_pressure)) {
          ++skipped;
          continue;
        }
        states.push_back({stampOf(s->header.stamp, m.getTime()), s->pressure[j], s->length[j], s->length_rate[j],
                          s->supply_pressure});
      } else if (auto c = m.instantiate<adroit_msgs::ValveCommand>()) {
        for (std::size_t k = 0; k < c->volts.size(); ++k) {
          const bool mine = k < c->name.size() ? c->name[k] == cylinder
                                               : (k < c->index.size() && c->index[k] == my_index);
          if (mine && std::isfinite(c->volts[k]))
            commands[stampOf(c->header.stamp, m.getTime())] = std::clamp(c->volts[k], -5.0, 5.0);
        }
      }
    }
    std::sort(states.begin(), states.end(), [](const Sample& a, const Sample& b) { return a.t < b.t; });
    if (states.size() < 2) throw std::runtime_error(bag_path + ": fewer than 2 actuator states of " + cylinder);
    if (commands.empty()) throw std::runtime_error(bag_path + ": no valve commands for " + cylinder);

    Recording rec;
    rec.dt = dt;
    std::size_t s = 0;
    for (double t = std::max(states.front().t, commands.begin()->first); t <= states.back().t; t += dt) {
      while (s + 2 < states.size() && states[s + 1].t <= t) ++s;
      const Sample& a = states[s];
      const Sample& b = states[s + 1];
      const double f = b.t > a.t ? std::clamp((t - a.t) / (b.t - a.t), 0.0, 1.0) : 0.0;
      auto lerp = [f](double x, double y) { return x + f * (y - x); };
      auto cmd = commands.upper_bound(t);
      --cmd;  // last command at or before t (t starts at or after the first command)
      rec.volts.push_back(cmd->second);
      rec.pressure.push_back(lerp(a.pressure, b.pressure));
      rec.volume.push_back(dead + me->bore_area * std::max(0.0, lerp(a.length, b.length)));
      rec.volume_rate.push_back(me->bore_area * lerp(a.rate, b.rate));
      rec.supply.push_back(lerp(a.supply, b.supply));
    }
    rec.validate();
    writeRecordingCsv(out, rec);
    std::printf("wrote %s: %zu samples of %s at %.4f s (%zu states, %zu commands, %zu bad states skipped)\n",
                out.c_str(), rec.size(), cylinder.c_str(), dt, states.size(), commands.size(), skipped);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pneumatic_sysid_bag: %s\n", e.what());
    return 1;
  }
  return 0;
}
