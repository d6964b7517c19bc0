#include "adroit_description/scenes.h"

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "adroit_core/bounded_file.h"

namespace adroit {
namespace description {

std::vector<std::string> sceneNames(const std::string& share_dir) {
  const std::string path = share_dir + "/scenes.txt";
  std::string text;
  try {
    text = adroit::readBoundedFile(path, adroit::kMiB);
  } catch (const adroit::FileError& e) {
    throw std::runtime_error(std::string("cannot read scene list: ") + e.what());
  }
  std::istringstream in(text);
  std::vector<std::string> names;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) names.push_back(line);
  }
  return names;
}

namespace {
void requireScene(const std::string& share_dir, const std::string& scene) {
  const auto names = sceneNames(share_dir);
  if (std::find(names.begin(), names.end(), scene) != names.end()) return;
  std::string known;
  for (const auto& n : names) known += (known.empty() ? "" : ", ") + n;
  throw std::invalid_argument("unknown scene '" + scene + "' (known: " + known + ")");
}
}  // namespace

std::string sceneFile(const std::string& share_dir, const std::string& scene, bool planning) {
  requireScene(share_dir, scene);
  return share_dir + "/mjcf/" + scene + (planning ? "_planning" : "") + ".xml";
}

std::string urdfFile(const std::string& share_dir, const std::string& scene) {
  requireScene(share_dir, scene);
  return share_dir + "/urdf/" + scene + ".urdf";
}

std::string packageShareDir(const std::string& package, const std::string& marker) {
  for (const char* variable : {"CMAKE_PREFIX_PATH", "ROS_PACKAGE_PATH"}) {
    const char* value = std::getenv(variable);
    if (!value) continue;
    std::stringstream list(value);
    std::string prefix;
    while (std::getline(list, prefix, ':')) {
      if (prefix.empty()) continue;
      for (const std::string& dir : {prefix + "/share/" + package, prefix + "/" + package})
        if (std::ifstream(dir + "/" + marker).good()) return dir;
    }
  }
  throw std::runtime_error(package + " not found on CMAKE_PREFIX_PATH or ROS_PACKAGE_PATH (source the workspace's "
                           "setup.bash)");
}

std::string descriptionShareDir() { return packageShareDir("adroit_description", "scenes.txt"); }

}  // namespace description
}  // namespace adroit
