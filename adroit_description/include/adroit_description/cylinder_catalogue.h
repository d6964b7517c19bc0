// The ADROIT cylinder catalogue and atmospheric pressure as compile-time constants.
//
// One source: config/cylinders.yaml. scripts/generate_model.py reads it at build time for the
// MJCF (actuator user data and custom text) and writes the same numbers into the generated
// header included below, so the model files and every C++ user (this library, the pneumatic
// plant, the driver) agree by construction and nothing has to find a file at run time.
// Header-only and ROS-free: a user needs adroit_description's include directory, not its
// library.
#pragma once

#include <cstddef>
#include <string_view>

namespace adroit {
namespace description {

struct CylinderType {
  std::string_view type;      // "M9", "M16", "M24", "M40"
  double bore_diameter;       // m
  double stroke;              // m
  double dead_volume;         // m^3, chamber volume at full retraction (tubes, end cap)
  double leak_diameter;       // m, equivalent orifice of the air seal
  int valve;                  // valve of thesis table 4.4 (1 or 2)
  double valve_scale;         // factor on that valve's port areas
};

}  // namespace description
}  // namespace adroit

// kAtmosphericPressure and kCylinderCatalogue[], generated from config/cylinders.yaml.
#include "adroit_description/cylinder_catalogue_data.h"

namespace adroit {
namespace description {

// Catalogue entry of a type, nullptr if there is none.
constexpr const CylinderType* findCylinderType(std::string_view type) {
  for (const CylinderType& c : kCylinderCatalogue) {
    if (c.type == type) return &c;
  }
  return nullptr;
}

}  // namespace description
}  // namespace adroit
