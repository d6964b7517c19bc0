// What mpc_success varies beyond what the tasks were tuned on (issue 38: robustness measured,
// not assumed): the object's mass and size in both worlds, the drop, the sensors' noise, the
// typed sequences; --sweep over one of them; and --set keys checked against the tasks, so an
// option or key that would change nothing is refused with one line instead of ignored.
#pragma once

#include <adroit_driver/sim_config.h>

#include <map>
#include <string>
#include <vector>

namespace success {

// The trials' world. The defaults are what the tasks were tuned on and what mpc_success ran
// before these options existed (makeTrials draws the same numbers with them).
struct World {
  double object_mass = 0;      // kg, body "object" of the simulation and the planning model; 0 keeps
  double object_scale = 1;     // size of that object in both (geoms and centre of mass; inertia ~ s^2)
  double drop_center = 0.065;  // m above the catch goal / the relocation hold: 4-9 cm
  double drop_half = 0.025;    //   (centre and half-range, so the default draws are bit for bit the old ones)
  double drop_offset = 0.015;  // m, sideways half-range in x and in y
  double sensor_noise = 1;     // factor on every noise std of the driver's sensors
  int keys = 10;               // typing: sequence length
  std::string key_set = "0123456789";  // typing: the digits a sequence is drawn from
};

// The names --sweep takes, which are also the options' (--object-mass is object_mass...).
const std::vector<std::string>& worldOptionNames();

// Sets option `name` from its text: object_mass KG, object_scale S, drop_height MIN,MAX (or H:
// always from H), drop_offset M, sensor_noise F, keys N, key_set DIGITS. Returns "" when
// good, else why in one line (the caller names the flag).
std::string setWorldOption(World& world, const std::string& name, const std::string& text);

// The options that differ from the tasks' tuning, by name.
std::vector<std::string> changedOptions(const World& world);

// Why option `name` would change nothing in a run of these tasks ("" when it would): an
// object or drop option without catch or relocate, a typing option without type, sensor noise
// that neither the planner (--sensed) nor a pool (pneumatic variants) reads.
std::string whyNoEffect(const std::string& name, const std::vector<std::string>& tasks, bool sensed,
                        bool pneumatic_variant);

// One line describing the options that differ from the tuning ("" when none), for the headers.
std::string describe(const World& world);

// The driver's sensors with every noise std multiplied by world.sensor_noise (quantisation and
// delays are the hardware's and stay).
void scaleSensorNoise(double factor, adroit::driver::SensorRealism& sensors);

// A scene for the simulation driver, which loads a file, with its object changed as the
// planning model's is (scaleObjectBody): the scene compiled, changed, saved as a MuJoCo
// binary in the temporary directory, removed with this object. Throws std::invalid_argument
// when the scene has no body "object".
class ObjectVariantScene {
 public:
  ObjectVariantScene(const std::string& scene_file, double mass, double scale);
  ~ObjectVariantScene();
  ObjectVariantScene(const ObjectVariantScene&) = delete;
  ObjectVariantScene& operator=(const ObjectVariantScene&) = delete;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

// --sweep name=v1,v2,...: every value is checked with setWorldOption.
struct Sweep {
  std::string name;
  std::vector<std::string> values;
};
// "" and *out set when good, else why in one line.
std::string parseSweep(const std::string& text, Sweep* out);

// Task parameters per task, from --set [task.]key=number.
using TaskNumbers = std::map<std::string, std::map<std::string, double>>;

// Resolves the --set texts against the tasks that run: a key without "task." must be a number
// parameter of every one of them, a scoped one of its task, and the merged parameters must
// make the task (ranges). Keys the benchmark does not read from the task (the planner hints:
// its own flags set them) or that no task reads (object_mass, object_radius: --object-mass,
// --object-scale) are refused. "" and *out filled when good, else one line.
std::string resolveTaskParams(const std::vector<std::string>& sets, const std::vector<std::string>& tasks,
                              TaskNumbers* out);

// A number from the whole of `text` (false for "", "1x", "nan"...).
bool parseNumber(const std::string& text, double* value);

}  // namespace success
