// Trained policies on disk: a versioned, self-describing text file. A header of `key value`
// lines says what the controller is for (task, scene, control step, the joints, cylinders and
// actions it was trained with, the state layout), then `matrices` and the controller's blocks
// in MatrixFile format (dims, K.t, k.t, C.t). Written atomically (temporary file, fsync,
// rename), so a crash or a full disk never leaves a half-written policy behind.
//
//   adroit_tvlg_policy 1
//   task position_with_gravity
//   ...
//   matrices
//   dims 1 3
//   ...
#pragma once
#include <adroit_learning/lg_controller.h>
#include <adroit_learning/matrix_file.h>

#include <stdexcept>
#include <string>
#include <vector>

namespace adroit {

constexpr int kPolicyFormatVersion = 1;
// A policy of nx 88, nu 40, T 50 takes about 6 MB.
constexpr std::size_t kMaxPolicyFileBytes = 256 * kMiB;

class PolicyFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct PolicyFile {
  std::string task, scene, state_layout;
  double control_dt = 0;
  int iteration = 0;
  double cost_mean = 0;  // of the rollouts this controller ran (NaN when not yet run)
  std::vector<std::string> joints, cylinders, actions;
  double locked_command = 0;
  LgController controller;
};

// Throws PolicyFileError naming the path when it cannot be written; the old file, if any,
// is then untouched.
void writePolicyFile(const std::string& path, const PolicyFile& policy);
// Throws PolicyFileError "<path>: <what is wrong>" for a missing, corrupt, truncated or
// other-version file, for anything but a regular file (a FIFO, a device, a directory) and for
// a file over kMaxPolicyFileBytes; sizes in its header are checked against its blocks before
// the controller is allocated.
PolicyFile readPolicyFile(const std::string& path);

// Checks a policy against the robot it is about to run on; returns "" when it fits, else one
// line naming the file and the mismatch (joints, cylinders, state size).
std::string policyMismatch(const PolicyFile& policy, const std::string& path, const std::vector<std::string>& joints,
                           const std::vector<std::string>& cylinders, const std::string& state_layout);

// Writes `text` to `path` atomically (same directory temporary, fsync, rename). Throws
// PolicyFileError naming the path.
void writeFileAtomically(const std::string& path, const std::string& text);

}  // namespace adroit
