// Shared fixtures of the description checks: the generated files and their expected counts.
#pragma once

#include <string>
#include <vector>

#include "adroit_core/mujoco_model.h"
#include "adroit_description/scenes.h"

namespace adroit_test {

inline std::string shareDir() { return ADROIT_DESCRIPTION_DIR; }

struct SceneFacts {
  std::string name;
  bool arm;        // 28-DOF arm-hand (48 cylinders) or hand-only (24 DOF, 40 cylinders)
  int object_qpos; // free object: 7, keypad: 12 keys, none: 0
  bool free_base = false;  // teleop: the hand base on a free joint welded to a mocap body
};

// From the issue: hand-only scenes have 40 cylinders, arm-hand 48; objects add a free joint.
inline std::vector<SceneFacts> expectedScenes() {
  return {{"hand", false, 0}, {"arm_hand", true, 0}, {"tube", false, 7}, {"pickup", false, 7},
          {"bottle", false, 7}, {"ball", true, 7},     {"keypad", false, 12},
          {"teleop_tube", false, 7, true}, {"teleop_ball", false, 7, true}};
}

inline adroit::LoadedModel loadScene(const std::string& scene, bool planning = false) {
  return adroit::loadModelFile(adroit::description::sceneFile(shareDir(), scene, planning));
}

// The 24 hand joints of the kinematics reference, in tree order.
inline std::vector<std::string> handJoints() {
  return {"WRJ1", "WRJ0", "FFJ3", "FFJ2", "FFJ1", "FFJ0", "MFJ3", "MFJ2", "MFJ1", "MFJ0", "RFJ3", "RFJ2",
          "RFJ1", "RFJ0", "LFJ4", "LFJ3", "LFJ2", "LFJ1", "LFJ0", "THJ4", "THJ3", "THJ2", "THJ1", "THJ0"};
}

}  // namespace adroit_test
