// The pneumatic cylinders of a compiled ADROIT model, read from the model itself:
// every tendon actuator carries user data [bore diameter, stroke] and a custom text
// "cylinder_<actuator>" naming its cylinder type (M9, M16, M24, M40).
#pragma once

#include <mujoco/mujoco.h>

#include <string>
#include <vector>

#include "adroit_description/cylinder_catalogue.h"  // kAtmosphericPressure, the catalogue

namespace adroit {
namespace description {

struct Cylinder {
  std::string name;     // actuator name, e.g. A_FFJ2_flex
  std::string type;     // catalogue type, e.g. M9
  int actuator = -1;
  int tendon = -1;
  double bore_diameter = 0;  // m
  double bore_area = 0;      // m^2
  double stroke = 0;         // m
  double max_tension = 0;    // N, the actuator's control upper limit
  // Tendon length at which the piston is fully retracted (chamber at its dead volume): the
  // longest the tendon gets within the joint limits. The chamber grows as the tendon shortens.
  double longest_tendon_length = 0;  // m
};

// Throws std::runtime_error naming the actuator when its data is missing or inconsistent
// (no user data, no type text, travel over the joint range longer than the stroke).
std::vector<Cylinder> cylinderTable(const mjModel* model);

// Piston travel from full retraction [m], clamped to [0, stroke].
double pistonTravel(const Cylinder& cylinder, double tendon_length);

}  // namespace description
}  // namespace adroit
