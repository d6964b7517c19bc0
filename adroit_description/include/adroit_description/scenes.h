// Where the generated ADROIT model files live and which scenes exist.
#pragma once

#include <string>
#include <vector>

namespace adroit {
namespace description {

// Scene names listed in <share_dir>/scenes.txt (written by the model generator).
// Throws std::runtime_error naming the file when it cannot be read.
std::vector<std::string> sceneNames(const std::string& share_dir);

// Path of a scene's MJCF (the planning variant adds thesis Table 6.1 springs and armature).
// Throws std::invalid_argument("unknown scene 'x' (known: ...)") for a name not in scenes.txt.
std::string sceneFile(const std::string& share_dir, const std::string& scene, bool planning = false);

// Path of the URDF of the robot in that scene (mount pose included).
std::string urdfFile(const std::string& share_dir, const std::string& scene);

// For ROS-free programs and tests: the first share/<package> (or <package>) directory of a
// prefix on CMAKE_PREFIX_PATH, then ROS_PACKAGE_PATH, that holds the file `marker`. Throws
// std::runtime_error naming the variables searched.
std::string packageShareDir(const std::string& package, const std::string& marker);
// adroit_description's own (the one with scenes.txt): where the generated models are.
std::string descriptionShareDir();

}  // namespace description
}  // namespace adroit
