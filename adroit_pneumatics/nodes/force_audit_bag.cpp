// force_tracking_audit: the pools' force tracking in a recorded run, next to the plant's
// floor (ForceTrackingAudit, tracking_floor.h), per group of cylinders.
//   force_tracking_audit --bag run.bag [--model scene.xml | --scene arm_hand] [--limit 2.0]
//                        [--min-tension 0.3] [--sensing-delay 0.001] [--floor-sensor sim|none] [--csv out.csv]
// The bag holds /adroit/actuator_states and /adroit/force_reference (e.g. `rosbag record`
// beside a bringup; scripts/demo.sh records one). At every actuator state after the first
// reference, the desired tension of each cylinder is the newest reference stamped at or
// before the state (by stamp, not by arrival at the recorder), interpolated at the state's
// stamp, as the pools take it; states outside that reference's span are skipped. The floors start from the first audited state's pressures and follow each
// cylinder's recorded piston travel and supply; --limit is the pools' command limit (V,
// config/pools.yaml ilqg/u_max); --min-tension the least tension the robot applies and
// reports (the simulation driver's ~min_tension; default 0), which the floors then pull too;
// --sensing-delay the delay of the measured tension behind the chamber (the simulation's
// ~sensors/cylinder_delay, 1 ms; the DAQ's on the robot), added to the tube delay: the floors
// learn of each desired value at the state it is first paired with and are seen through the
// same delays. --floor-sensor sim (default): the floors' pressures are read through the
// simulation driver's pressure sensor (its default ~sensors: 2 kPa noise, 16-bit quantum,
// 500 Hz low-pass), the sensor the measured tension comes from, so measured and floor carry the
// same sensing error; none: the exact chambers (the floor before issue 38). Also printed: the
// largest step of the plans' tensions from one knot to the next per group, and RESULT lines of
// the RMSE over the per-sample floor (target 1.3, issue 38). Also printed: how far each reference's preview (5 / 10 / 20 ms ahead) was from
// the desired value as it came, and RESULT lines of the RMSE per finger group (target 0.5 N,
// issue 12) with the floor beside each, the bound the plant and its sensing set on this run.
// --csv writes time, desired and measured tension and the per-sample floor's tension per
// cylinder (time in seconds from the first audited state).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <iomanip>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include <ros/package.h>
#include <rosbag/bag.h>
#include <rosbag/view.h>

#include <adroit_msgs/ActuatorStates.h>
#include <adroit_msgs/ForceReference.h>

#include "adroit_core/bounded_file.h"
#include "adroit_description/scenes.h"
#include "adroit_pneumatics/plant.h"
#include "adroit_pneumatics/pool.h"
#include "adroit_pneumatics/tracking_floor.h"

using namespace adroit::pneumatics;

namespace {

constexpr const char* kUsage =
    "usage: force_tracking_audit --bag run.bag [--model f.xml | --scene arm_hand] [--limit 2.0] [--min-tension 0.3]\n"
    "                            [--sensing-delay 0.001] [--floor-sensor sim|none] [--csv out.csv]\n";
constexpr double kTargetRmse = 0.5;  // N per finger group (issue 12 item 5)
constexpr double kTargetFloorRatio = 1.3;  // RMSE over the sensed per-sample floor (issue 38)
const std::vector<double> kPreviewLeads = {0.005, 0.01, 0.02};  // s

// The reference's value for column j at time t (linear between samples), NaN outside it.
double desiredAt(const adroit_msgs::ForceReference& ref, std::size_t j, double t) {
  const std::size_t n = ref.name.size();
  const double x = (t - ref.header.stamp.toSec()) / ref.dt;
  if (!(x >= 0) || x > static_cast<double>(ref.steps - 1)) return std::nan("");
  const auto k0 = static_cast<std::size_t>(x);
  const std::size_t k1 = std::min<std::size_t>(k0 + 1, ref.steps - 1);
  const double a = x - static_cast<double>(k0);
  return (1 - a) * ref.force[k0 * n + j] + a * ref.force[k1 * n + j];
}

// A reference the audit can use: a stamp, positive dt, steps x names forces.
bool usable(const adroit_msgs::ForceReference& ref) {
  return !ref.header.stamp.isZero() && ref.dt > 0 && std::isfinite(ref.dt) && ref.steps > 0 &&
         ref.force.size() == static_cast<std::size_t>(ref.steps) * ref.name.size();
}

constexpr int kMaxShift = 50;  // samples

// The shift (in samples, interpolated) by which the floor's trace must lag the desired one to
// reach the RMSE `target` over the group's cylinders: the measured excess over the floor
// expressed as a delay. NaN when even kMaxShift samples are not enough.
double latencyEquivalent(const std::vector<std::vector<double>>& desired, const std::vector<std::vector<double>>& floor,
                         const std::vector<std::size_t>& members, double target) {
  const auto rmse = [&](int shift) {
    double sq = 0;
    long n = 0;
    for (std::size_t k = 0; k < desired.size(); ++k) {
      const std::size_t from = k >= static_cast<std::size_t>(shift) ? k - shift : 0;
      for (std::size_t j : members) {
        const double e = floor[from][j] - desired[k][j];
        if (std::isfinite(e)) sq += e * e, ++n;
      }
    }
    return n > 0 ? std::sqrt(sq / n) : 0.0;
  };
  double previous = rmse(0);
  if (previous >= target) return 0.0;
  for (int shift = 1; shift <= kMaxShift; ++shift) {
    const double now = rmse(shift);
    if (now >= target) return shift - 1 + (target - previous) / std::max(now - previous, 1e-12);
    previous = now;
  }
  return std::nan("");
}

}  // namespace

int main(int argc, char** argv) {
  std::string bag_path, model_file, scene = "arm_hand", csv_path, floor_sensor = "sim";
  double limit = 2.0, min_tension = 0.0, sensing_delay = 0.001;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) {
      std::fprintf(stderr, "force_tracking_audit: %s needs a value\n%s", a.c_str(), kUsage);
      return 2;
    }
    const std::string v = argv[++i];
    if (a == "--bag") bag_path = v;
    else if (a == "--model") model_file = v;
    else if (a == "--scene") scene = v;
    else if (a == "--csv") csv_path = v;
    else if (a == "--limit") limit = std::atof(v.c_str());
    else if (a == "--min-tension") min_tension = std::atof(v.c_str());
    else if (a == "--sensing-delay") sensing_delay = std::atof(v.c_str());
    else if (a == "--floor-sensor") floor_sensor = v;
    else {
      std::fprintf(stderr, "force_tracking_audit: unknown argument %s\n%s", a.c_str(), kUsage);
      return 2;
    }
  }
  if (floor_sensor != "sim" && floor_sensor != "none") {
    std::fprintf(stderr, "force_tracking_audit: --floor-sensor must be sim or none (got '%s')\n", floor_sensor.c_str());
    return 2;
  }
  if (bag_path.empty() || !(limit > 0) || !(min_tension >= 0) || !std::isfinite(min_tension) ||
      !(sensing_delay >= 0 && sensing_delay <= 0.05)) {
    std::fprintf(stderr, "%s", kUsage);
    return 2;
  }
  try {
    if (model_file.empty())
      model_file = adroit::description::sceneFile(ros::package::getPath("adroit_description"), scene);
    const auto table = loadModelCylinders(model_file);

    // A FIFO would block rosbag's open for good; a bag of a day's recording is far below this.
    adroit::requireRegularFile(bag_path, 64 * adroit::kGiB);
    rosbag::Bag bag(bag_path, rosbag::bagmode::Read);
    rosbag::View view(bag, rosbag::TopicQuery(std::vector<std::string>{"/adroit/actuator_states",
                                                                       "/adroit/force_reference"}));
    adroit_msgs::ForceReference::ConstPtr ref;
    std::vector<std::string> names;         // audited cylinders: the first reference's that the model has
    std::vector<std::size_t> in_reference;  // their columns in the reference (resolved per reference)
    std::vector<double> volume_area, dead;  // per audited cylinder
    std::unique_ptr<ForceTrackingAudit> audit;
    std::unique_ptr<PreviewAudit> preview;
    std::vector<double> given;  // a reference's rows in the audited columns
    std::unique_ptr<ReferenceStepAudit> steps;  // per group: the plans' tension changes from one knot to the next
    std::vector<double> desired, tension, volume, volume_rate, pressure;
    std::ofstream csv;
    // Per audited sample (after the first): its time, desired and per-sample floor tensions,
    // for the latency equivalent of the excess below.
    std::vector<double> times;
    std::vector<std::vector<double>> desired_log, floor_log;
    double last_t = 0, first_t = 0;
    std::size_t states = 0, audited = 0, skipped = 0, references = 0, bad_references = 0;
    // The recorder receives references late and in bursts when the machine is busy (the MPC
    // publishes one per control period): the pools had each from about its stamp on. So each
    // state is paired with the newest reference stamped at or before it, not the newest the
    // bag happened to hold.
    std::vector<adroit_msgs::ForceReference::ConstPtr> reference_msgs;
    std::vector<adroit_msgs::ActuatorStates::ConstPtr> state_msgs;
    for (const rosbag::MessageInstance& m : view) {
      if (auto r = m.instantiate<adroit_msgs::ForceReference>()) {
        if (usable(*r)) reference_msgs.push_back(r);
        else ++bad_references;
      } else if (auto s = m.instantiate<adroit_msgs::ActuatorStates>()) {
        state_msgs.push_back(s);
      }
    }
    references = reference_msgs.size();
    const auto by_stamp = [](const auto& a, const auto& b) { return a->header.stamp < b->header.stamp; };
    std::stable_sort(reference_msgs.begin(), reference_msgs.end(), by_stamp);
    std::stable_sort(state_msgs.begin(), state_msgs.end(), by_stamp);
    if (!reference_msgs.empty()) {
      const auto& r = reference_msgs.front();
      {
        std::vector<ForceTrackingAudit::Cylinder> cylinders;
        for (const std::string& n : r->name) {
          const auto c = std::find_if(table.begin(), table.end(), [&](const auto& x) { return x.name == n; });
          if (c == table.end()) continue;
          CylinderSpec spec = cylinderSpec(c->type);
          spec.dead_volume = deadVolume(c->type, c->bore_diameter);
          spec.bore_area = c->bore_area;
          cylinders.push_back({trackingGroup(n), spec});
          names.push_back(n);
          volume_area.push_back(c->bore_area);
          dead.push_back(spec.dead_volume);
        }
        if (names.empty()) throw std::runtime_error("the first force reference names no cylinder of " + model_file);
        std::vector<std::string> groups;
        for (const auto& c : cylinders) groups.push_back(c.group);
        audit = std::make_unique<ForceTrackingAudit>(std::move(cylinders), limit, PlantOptions{}.tube_delay + sensing_delay);
        preview = std::make_unique<PreviewAudit>(groups, kPreviewLeads);
        steps = std::make_unique<ReferenceStepAudit>(groups);
        audit->setMinTension(min_tension);
        if (floor_sensor == "sim") audit->setSensor(SensorParams{});
        if (!csv_path.empty()) {
          csv.open(csv_path);
          if (!csv) throw std::runtime_error("--csv: cannot write " + csv_path);
          csv << "time";
          for (const auto& n : names) csv << ',' << n << ":desired";
          for (const auto& n : names) csv << ',' << n << ":measured";
          for (const auto& n : names) csv << ',' << n << ":floor_per_sample";
          csv << '\n';
        }
      }
    }
    std::size_t next_reference = 0;
    for (const auto& s : state_msgs) {
      ++states;
      while (next_reference < reference_msgs.size() && reference_msgs[next_reference]->header.stamp <= s->header.stamp) {
        ref = reference_msgs[next_reference++];
        if (!preview) continue;
        // Its rows in the audited columns (a reference that misses one is left out).
        given.assign(ref->steps * names.size(), 0.0);
        bool all = true;
        for (std::size_t j = 0; j < names.size() && all; ++j) {
          const auto col = std::find(ref->name.begin(), ref->name.end(), names[j]) - ref->name.begin();
          all = col < static_cast<long>(ref->name.size());
          for (std::size_t k = 0; all && k < ref->steps; ++k)
            given[k * names.size() + j] = ref->force[k * ref->name.size() + static_cast<std::size_t>(col)];
        }
        if (!all) continue;
        preview->addReference(ref->header.stamp.toSec(), ref->dt, ref->steps, given);
        steps->addReference(ref->steps, given.data(), given.size());
      }
      if (!audit || !ref) continue;
      const std::size_t n = s->name.size();
      if (s->pressure.size() != n || s->length.size() != n || s->length_rate.size() != n || s->force.size() != n ||
          !std::isfinite(s->supply_pressure) || s->header.stamp.isZero()) {
        ++skipped;
        continue;
      }
      const double t = s->header.stamp.toSec();
      const std::size_t k = names.size();
      desired.assign(k, std::nan(""));
      tension.assign(k, std::nan(""));
      volume.assign(k, 0.0);
      volume_rate.assign(k, 0.0);
      pressure.assign(k, std::nan(""));
      bool complete = true;
      for (std::size_t j = 0; j < k && complete; ++j) {
        const auto col = std::find(ref->name.begin(), ref->name.end(), names[j]) - ref->name.begin();
        const auto row = std::find(s->name.begin(), s->name.end(), names[j]) - s->name.begin();
        if (col == static_cast<long>(ref->name.size()) || row == static_cast<long>(n)) {
          complete = false;
          break;
        }
        desired[j] = desiredAt(*ref, static_cast<std::size_t>(col), t);
        tension[j] = s->force[row];
        pressure[j] = s->pressure[row];
        volume[j] = dead[j] + volume_area[j] * std::max(0.0, s->length[row]);
        volume_rate[j] = volume_area[j] * s->length_rate[row];
        complete = std::isfinite(desired[j]) && std::isfinite(tension[j]) && std::isfinite(volume[j]) &&
                   std::isfinite(volume_rate[j]);
      }
      if (!complete) {
        ++skipped;
        continue;
      }
      if (audited == 0) audit->start(pressure);
      else {
        audit->add(t - last_t, desired, tension, volume, volume_rate, s->supply_pressure);
        preview->addSample(t, desired);
        times.push_back(t);
        desired_log.push_back(desired);
        floor_log.push_back(audit->lastPerTickTension());
      }
      last_t = t;
      ++audited;
      if (csv.is_open()) {
        if (audited == 1) first_t = t;
        csv << std::fixed << std::setprecision(4) << t - first_t << std::defaultfloat << std::setprecision(6);
        for (double v : desired) csv << ',' << v;
        for (double v : tension) csv << ',' << v;
        for (std::size_t j = 0; j < k; ++j)
          csv << ',' << (audited > 1 ? audit->lastPerTickTension()[j] : tension[j]);
        csv << '\n';
      }
    }
    if (!audit || audited < 2)
      throw std::runtime_error(bag_path + ": no actuator state inside a force reference (" + std::to_string(states) +
                               " states, " + std::to_string(references) + " references)");
    std::printf("force tracking in %s: %zu actuator states audited (%zu skipped), %zu references (%zu unusable)\n",
                bag_path.c_str(), audited, skipped, references, bad_references);
    std::printf("measured vs desired tendon tension, RMSE in N, next to the plant's floor: a cylinder that learns of\n"
                "each desired value at the state it is first paired with, races at the command limit (+-%.1f V)\n"
                "towards it after %.0f ms (the plant's %.0f ms tube delay and %.0f ms of sensing) and stops on it\n"
                "exactly, and per sample: one command per state sample, chosen with an exact model; the robot's\n"
                "minimum tension %.2f N bounds measured and floors alike. preview: how far the reference given\n"
                "5 / 10 / 20 ms earlier was from the desired value as it came\n",
                limit, (PlantOptions{}.tube_delay + sensing_delay) * 1e3, PlantOptions{}.tube_delay * 1e3,
                sensing_delay * 1e3, min_tension);
    std::printf("floors %s\n", floor_sensor == "sim" ? "read through the simulation's pressure sensor (noise, quantum, low-pass)"
                                                     : "exact (no sensor)");
    std::printf("  %-6s %7s %7s %10s %10s %8s %9s %9s %9s %20s\n", "group", "RMSE", "floor", "per sample", "RMSE/floor",
                "max ref", "max step", "p99 step", "as delay", "preview 5/10/20 ms");
    const auto ahead = preview->groups();
    const double spacing = times.size() > 1 ? (times.back() - times.front()) / static_cast<double>(times.size() - 1) : 0;
    for (const auto& [group, g] : audit->groups()) {
      std::vector<std::size_t> members;
      for (std::size_t j = 0; j < names.size(); ++j)
        if (trackingGroup(names[j]) == group) members.push_back(j);
      const double delay = latencyEquivalent(desired_log, floor_log, members, g.rmse);
      char as_delay[32];
      if (std::isfinite(delay)) std::snprintf(as_delay, sizeof as_delay, "%.1f ms", delay * spacing * 1e3);
      else std::snprintf(as_delay, sizeof as_delay, "> %d ms", static_cast<int>(kMaxShift * spacing * 1e3));
      char previewed[64] = "-";
      if (ahead.count(group) && ahead.at(group).size() == kPreviewLeads.size() && std::isfinite(ahead.at(group)[0]))
        std::snprintf(previewed, sizeof previewed, "%.2f / %.2f / %.2f", ahead.at(group)[0], ahead.at(group)[1],
                      ahead.at(group)[2]);
      std::printf("  %-6s %7.2f %7.2f %10.2f %10.2f %8.1f %9.1f %9.1f %9s %20s\n", group.c_str(), g.rmse, g.floor,
                  g.per_tick, g.per_tick > 0 ? g.rmse / g.per_tick : 0.0, g.max_reference, steps->largest(group),
                  steps->percentile99(group), as_delay, previewed);
    }
    std::printf("(max step, p99 step: the largest change of a plan's tension from one knot to the next and its\n"
                " 99th percentile, N;\n"
                " as delay: how late the per-sample floor would have to act to be as far off as the measured\n"
                "tension: its trace shifted by that much against the desired one has the measured RMSE)\n\n");
    // The figure of issue 12 item 5 per finger group, each with the bound of this run beside
    // it: where the floor is above the target, no controller that learns of the plan's values
    // as they come reaches it (and the preview column says whether the plans' previews knew more).
    for (const auto& [group, g] : audit->groups()) {
      if (group == "wrist" || group == "arm") continue;
      std::printf("RESULT adroit_pneumatics/demo_force_rmse_%s %.2f N target <= %.1f %s\n", group.c_str(), g.rmse,
                  kTargetRmse, g.rmse <= kTargetRmse ? "PASS" : "FAIL");
      std::printf("  bound: the plant's floor on this run %.2f N (%s 0.5 N), the pools %.2f x the per-sample floor\n",
                  g.floor, g.floor > kTargetRmse ? "above" : "below", g.per_tick > 0 ? g.rmse / g.per_tick : 0.0);
      const double ratio = g.per_tick > 0 ? g.rmse / g.per_tick : std::nan("");
      std::printf("  the plans' tension step per knot: largest %.1f N, 99th percentile %.1f N; the floor %s\n",
                  steps->largest(group), steps->percentile99(group),
                  floor_sensor == "sim" ? "read through the sensor" : "exact");
      std::printf("RESULT adroit_pneumatics/demo_force_floor_ratio_%s %.2f ratio target <= %.1f %s\n", group.c_str(), ratio,
                  kTargetFloorRatio, ratio <= kTargetFloorRatio ? "PASS" : "FAIL");
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "force_tracking_audit: %s\n", e.what());
    return 1;
  }
  return 0;
}
