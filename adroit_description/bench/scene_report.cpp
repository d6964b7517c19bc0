// Loads ADROIT scenes, steps each with zero control and prints one row per scene:
//   scene, nq, nv, nu, contacts (mean over the run), steps/s, real-time factor.
// With --testspeed it also runs MuJoCo's own testspeed sample on the same file, as the
// baseline, and prints the ratio (this is the description's benchmark program).
//
// usage: scene_report [--dir SHARE_DIR] [--scene NAME]... [--planning] [--seconds S] [--testspeed]
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "adroit_core/mujoco_model.h"
#include "adroit_core/run_program.h"
#include "adroit_core/timing_stats.h"
#include "adroit_description/scenes.h"

namespace {

struct Options {
  std::string dir;
  std::vector<std::string> scenes;
  bool planning = false;
  double seconds = 3.0;
  bool testspeed = false;
};

// install/lib/adroit_description/scene_report -> install/share/adroit_description
std::string defaultShareDir() {
  char exe[4096];
  const ssize_t n = readlink("/proc/self/exe", exe, sizeof(exe) - 1);
  if (n <= 0) return ".";
  exe[n] = '\0';
  std::string path(exe);
  for (int up = 0; up < 3; ++up) path = path.substr(0, path.find_last_of('/'));
  return path + "/share/adroit_description";
}

Options parse(int argc, char** argv) {
  Options o;
  o.dir = defaultShareDir();
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument("option " + arg + " needs a value");
      return argv[++i];
    };
    if (arg == "--dir") o.dir = value();
    else if (arg == "--scene") o.scenes.push_back(value());
    else if (arg == "--planning") o.planning = true;
    else if (arg == "--testspeed") o.testspeed = true;
    else if (arg == "--seconds") {
      const std::string v = value();
      char* end = nullptr;
      o.seconds = std::strtod(v.c_str(), &end);
      if (*end != '\0' || !(o.seconds > 0) || o.seconds > 3600) {
        throw std::invalid_argument("--seconds must be a number in (0, 3600], got '" + v + "'");
      }
    } else {
      throw std::invalid_argument("unknown option '" + arg +
                                  "' (usage: scene_report [--dir D] [--scene NAME]... [--planning] "
                                  "[--seconds S] [--testspeed])");
    }
  }
  return o;
}

struct Row {
  std::string scene;
  int nq, nv, nu, ntendon;
  double contacts, steps_per_second, realtime_factor, testspeed_steps_per_second = 0;
  int warnings;
};

Row measure(const std::string& scene, const std::string& file, double seconds) {
  adroit::LoadedModel loaded = adroit::loadModelFile(file);
  if (!loaded.warning.empty()) {
    throw adroit::ModelLoadError("model '" + file + "' compiled with a warning: " + loaded.warning);
  }
  const mjModel* m = loaded.model.get();
  adroit::DataPtr d = adroit::makeData(m);
  const long steps = static_cast<long>(seconds / m->opt.timestep);
  for (int i = 0; i < 50; ++i) mj_step(m, d.get());  // warm caches
  mj_resetData(m, d.get());
  double contacts = 0;
  adroit::Stopwatch watch;
  for (long i = 0; i < steps; ++i) {
    mj_step(m, d.get());
    contacts += d->ncon;
  }
  const double wall = watch.elapsed();
  return {scene, m->nq, m->nv, m->nu, m->ntendon, contacts / steps, steps / wall,
          steps * m->opt.timestep / wall, 0, adroit::warningCount(d.get())};
}

// Runs MuJoCo's testspeed sample (libmujoco-samples) on the file: the baseline.
double testspeedStepsPerSecond(const std::string& file, long steps) {
  adroit::ProgramOptions options;
  options.timeout_s = 600;
  options.capture_output = true;
  options.merge_stderr = true;
  const auto run = adroit::runProgram({"mujoco-testspeed", file, std::to_string(steps), "1", "0"}, options);
  if (!run.ok()) return 0;
  double sps = 0;
  std::istringstream lines(run.output);
  for (std::string line; std::getline(lines, line);) {
    const auto at = line.find("Steps per second");
    const auto colon = at == std::string::npos ? at : line.find(':', at);
    if (colon != std::string::npos) sps = std::atof(line.c_str() + colon + 1);
  }
  return sps;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    Options o = parse(argc, argv);
    if (o.scenes.empty()) o.scenes = adroit::description::sceneNames(o.dir);
    std::vector<Row> rows;
    for (const auto& scene : o.scenes) {
      const std::string file = adroit::description::sceneFile(o.dir, scene, o.planning);
      Row row = measure(scene, file, o.seconds);
      if (o.testspeed) {
        row.testspeed_steps_per_second =
            testspeedStepsPerSecond(file, static_cast<long>(o.seconds / 0.002));
      }
      rows.push_back(row);
    }
    std::printf("%-10s %4s %4s %4s %8s %9s %10s %7s", "scene", "nq", "nv", "nu", "tendons", "contacts",
                "steps/s", "RTF");
    if (o.testspeed) std::printf(" %18s %8s", "testspeed steps/s", "ratio");
    std::printf(" %8s\n", "warnings");
    for (const auto& r : rows) {
      std::printf("%-10s %4d %4d %4d %8d %9.2f %10.0f %7.1f", r.scene.c_str(), r.nq, r.nv, r.nu, r.ntendon,
                  r.contacts, r.steps_per_second, r.realtime_factor);
      if (o.testspeed) {
        std::printf(" %18.0f %8.2f", r.testspeed_steps_per_second,
                    r.testspeed_steps_per_second > 0 ? r.steps_per_second / r.testspeed_steps_per_second : 0.0);
      }
      std::printf(" %8d\n", r.warnings);
    }
    if (o.testspeed) {
      for (const auto& r : rows) {
        const double ratio = r.testspeed_steps_per_second > 0 ? r.steps_per_second / r.testspeed_steps_per_second : 0;
        std::printf("RESULT adroit_description/steps_per_second_ratio_%s %.2f ratio target >= 0.9 %s\n",
                    r.scene.c_str(), ratio, ratio >= 0.9 ? "PASS" : "FAIL");
      }
    }
    for (const auto& r : rows) {
      if (r.warnings > 0) {
        std::fprintf(stderr, "scene_report: scene '%s' raised %d MuJoCo warnings\n", r.scene.c_str(), r.warnings);
        return 1;
      }
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "scene_report: %s\n", e.what());
    return 2;
  }
}
