// The planning model of the behaviour MPC (thesis 6.4.3-6.4.4, table 6.3): the scene's
// <scene>_planning.xml (table 6.1 springs and armature, pruned contacts) with the planner's
// settings applied: timestep = planner dt, sensors off, smooth contacts, object overrides.
#pragma once

#include <adroit_core/mujoco_model.h>
#include <adroit_description/scenes.h>

#include <mujoco/mujoco.h>

#include <string>

namespace adroit_mpc {

struct PlanningModelSettings {
  double timestep = 0.005;         // s; must equal PlannerSettings::dt
  bool disable_sensors = true;     // the planner reads no sensor: mjDSBL_SENSOR
  // Table 6.3 "mindist": contacts are generated this far before touching (geom and pair
  // margin), so the optimiser sees them coming. 0 keeps the model's margins.
  double contact_margin = 0.01;    // m (dynamic manipulation 0.01, typing 0.001)
  // Table 6.3 "contact softness": the penetration over which the constraint stiffens
  // (solimp width); solref's time constant is kept at least 2 timesteps (stable at dt).
  double contact_softness = 0.005; // m (dynamic manipulation 0.005, typing 0.001); 0 keeps
  // Constraint solver iterations per step (model: 20); fewer bound the cost of a step with
  // many contacts (the warm start keeps them accurate along a trajectory). 0 keeps the model's.
  int solver_iterations = 0;
  double object_mass = 0;          // kg, body "object" (inertia scaled with it); 0 keeps
  double object_size_scale = 1;    // geometric scale of the object's geoms (inertia ~ s^2)
  // The robot's slack-avoiding minimum tendon tension (thesis 6.3; the driver's ~min_tension):
  // the plant never applies less, in force and in pneumatic mode, so each tendon actuator's
  // lower control bound is raised to it and the planner plans only tensions the robot applies
  // (the pools are never asked for a tension below what a vented cylinder gives). 0 keeps.
  double min_tension = 0.3;        // N
  // Collide through explicit pairs only (explicitContactPairsXml below): the contacts of the
  // model's own collision filter without MuJoCo's broadphase. false keeps dynamic collisions.
  bool explicit_pairs = true;
};

// Applies the settings to a compiled model in place. Throws std::invalid_argument with one
// line naming the bad setting (non-positive timestep, negative margin, object override on a
// scene without a body "object").
void applyPlanningSettings(mjModel* model, const PlanningModelSettings& settings);

// Body "object" of a compiled model (the planning model's, or the simulated world's, so both
// change alike): mass set to `mass` kg (0 keeps it; inertia scaled with it), its geoms' sizes
// and positions and its centre of mass scaled by `size_scale` (inertia ~ s^2), the derived
// constants recomputed. False, the model unchanged, when it has no body "object"; throws
// std::invalid_argument for a negative mass or a non-positive scale.
bool scaleObjectBody(mjModel* model, double mass, double size_scale);

// The MJCF text of a model file: a regular file of at most 16 MB (adroit/bounded_file.h).
// Throws adroit::ModelLoadError, naming the file, when it cannot be read.
std::string readModelText(const std::string& path);

// Every geom pair MuJoCo 2.2.2's dynamic collision mechanism would test in `compiled` (the
// model of `xml`): contype/conaffinity, different weld bodies, the parent filter, <exclude>s,
// body pairs without an explicit pair, written into the MJCF text as explicit <pair>s with
// the parameters MuJoCo mixes for them (priority, condim and friction max, solmix-weighted
// solref / solimp, margin and gap max). A model compiled from it with opt.collision =
// mjCOL_PAIR has the same contacts without the broadphase, which on the planning models
// costs more than the narrow phase (keypad: 76 against 35 us per collision pass). Returns ""
// when a geom of such a pair has no name (nothing to write); `pairs` (optional): how many.
std::string explicitContactPairsXml(const std::string& xml, const mjModel* compiled, int* pairs = nullptr);

// Loads the planning MJCF and applies the settings. Throws adroit::ModelLoadError or
// std::invalid_argument.
adroit::ModelPtr loadPlanningModel(const std::string& path, const PlanningModelSettings& settings);

// The same scene without contact pruning: every hand geom collides with every other
// non-adjacent geom (MuJoCo's parent-child filter) and the object, all with condim 3, and
// the explicit pairs are gone. For the benchmark's before/after contact count (thesis
// 6.4.3: 40 -> 20). Rewrites the generated MJCF text; throws std::invalid_argument when
// the text has no hand geoms to unprune (not an ADROIT model).
std::string unprunedXml(const std::string& xml);
adroit::ModelPtr loadUnprunedPlanningModel(const std::string& path, const PlanningModelSettings& settings);

// Where ROS-free programs and tests find installed files (adroit_description/scenes.h).
using adroit::description::descriptionShareDir;
using adroit::description::packageShareDir;

// Contact points of the last collision pass that entered the constraint set (within their
// margin, not excluded): what the solver pays for.
int activeContacts(const mjData* data);

}  // namespace adroit_mpc
