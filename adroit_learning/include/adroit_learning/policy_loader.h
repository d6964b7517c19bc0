// Loads any policy file by its first word, so execute_policy and the evaluation program run
// every kind through one call: `adroit_tvlg_policy` (TvlgPolicy), `adroit_policy_library`
// (LibraryPolicy) and whatever a reader was registered for. The network policy's reader lives
// in adroit_learning_network (libtorch), which registers it here, so this core library never
// depends on torch:
//
//   registerPolicyReader("adroit_network_policy", readNetworkPolicy);  // at the program's start
//
// Without it, a network policy file is refused with "<path>: network policies need
// adroit_learning_network".
#pragma once
#include <adroit_learning/pickup.h>
#include <adroit_learning/policy.h>
#include <adroit_learning/policy_file.h>

#include <functional>
#include <memory>
#include <string>

namespace adroit {

// What a policy file says it is for besides the policy itself: the task to run it with (and
// so the robot's layout and cost), its scene and control step.
struct PolicyOrigin {
  std::string format;  // the file's first word, e.g. adroit_tvlg_policy
  std::string task, scene;
  double control_dt = 0;
};

// What a reader may need beyond the file.
struct PolicyContext {
  // The free object's geometry in a scene (the tube's axis in its body): a library reads the
  // tube's yaw with it. Unset: a library is refused.
  std::function<ObjectGeometry(const std::string& scene)> object_geometry;
};

// Reads the policy at `path`, fills `origin`, and throws PolicyFileError "<path>: <what>"
// when it cannot.
using PolicyReader =
    std::function<std::unique_ptr<Policy>(const std::string& path, const PolicyContext& context, PolicyOrigin& origin)>;

// Makes `reader` the reader of files whose first word is `first_word` (replacing any earlier
// one, also a built-in). Thread-safe; returns true so a static initialiser can call it.
bool registerPolicyReader(const std::string& first_word, PolicyReader reader);

// The policy at `path` (a regular file; its first line read bounded, then the whole file by its
// reader with that reader's limit); `origin`, when given, says what it is for. Throws
// PolicyFileError naming the file: missing, not a regular file, a format without a reader, or
// whatever its reader refuses.
std::unique_ptr<Policy> loadPolicy(const std::string& path, const PolicyContext& context = {},
                                   PolicyOrigin* origin = nullptr);

}  // namespace adroit
