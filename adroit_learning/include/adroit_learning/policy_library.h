// Generalisation by nearest neighbour (thesis 11.5): a library of local TVLG policies, each
// trained for one initial yaw of the tube; at the start of an execution the library observes
// the tube's yaw and runs the local policy trained for the nearest one.
//
// A library file is versioned text, one local policy per line; a relative policy path is
// relative to the library file's directory:
//
//   adroit_policy_library 1
//   task pickup
//   scene tube
//   policy 0 pickup_yaw000/final.tvlg
//   policy 90 pickup_yaw090/final.tvlg
#pragma once
#include <adroit_learning/pickup.h>
#include <adroit_learning/policy.h>
#include <adroit_learning/policy_file.h>
#include <adroit_learning/tvlg_policy.h>

#include <memory>
#include <string>
#include <vector>

namespace adroit {

constexpr int kPolicyLibraryFormatVersion = 1;
constexpr std::size_t kMaxPolicyLibraryFileBytes = 1 * kMiB;

struct PolicyLibraryEntry {
  double yaw_deg = 0;  // the tube's initial yaw the local policy was trained for, [0, 180)
  std::string path;    // as in the library file (relative to its directory, or absolute)
  // Set by readPolicyLibrary (the file at `path`); not needed to write a library.
  std::shared_ptr<const PolicyFile> policy;
  std::string resolved_path;
};

struct PolicyLibrary {
  std::string task, scene;
  std::vector<PolicyLibraryEntry> entries;
  std::vector<double> yaws() const;
};

// Throws PolicyFileError "<path>: <what>" for anything but a regular file of at most
// kMaxPolicyLibraryFileBytes, another format or version, a library without policies, an
// angle that is not finite or outside [0, 180), a duplicate angle, a local policy file that
// readPolicyFile refuses, or local policies of another task or scene than the library's, or
// that differ from each other in state layout, joints, cylinders, actions, control step or horizon.
PolicyLibrary readPolicyLibrary(const std::string& path);
// Writes the library's task, scene and entries (yaw, path) atomically. Throws PolicyFileError
// for what readPolicyLibrary would refuse in them (angles, names with spaces or newlines).
void writePolicyLibrary(const std::string& path, const PolicyLibrary& library);

// The index of the yaw nearest to `observed_yaw_deg` in angle modulo 180 degrees (the tube is
// symmetric end to end: 179 is 1 degree from 0); ties go to the lower index. -1 when `yaws_deg`
// is empty or the observed yaw is not finite.
int nearestPolicyIndex(const std::vector<double>& yaws_deg, double observed_yaw_deg);

// Nearest-neighbour policy (kind "library"): start(x_0) reads the object's orientation from
// x_0, picks the local policy of the nearest yaw and delegates every action to it.
class LibraryPolicy : public Policy {
 public:
  // `object`: the scene's tube geometry (axis in the body), by which the yaw is read. Throws
  // PolicyFileError when the library's state layout has no object rotation.
  LibraryPolicy(std::shared_ptr<const PolicyLibrary> library, const ObjectGeometry& object, std::string path);

  std::string kind() const override { return "library"; }
  int horizon() const override { return locals_.front().horizon(); }
  // Throws std::invalid_argument for a state without a finite object rotation or a vertical tube.
  void start(const Eigen::Ref<const Eigen::VectorXd>& x0) override;
  // Throws std::logic_error before start().
  void action(int t, const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& touch,
              Eigen::Ref<Eigen::VectorXd> u) override;
  // The first local policy's mismatch, or a layout without the object.
  std::string mismatch(const std::vector<std::string>& joints, const std::vector<std::string>& cylinders,
                       const std::vector<std::string>& touch, const StateLayout& layout) const override;

  // After start(): the chosen local policy (index into the library's entries, -1 before), the
  // yaw it was trained for and the yaw observed in x_0 (for logs and evaluation).
  int selected() const { return selected_; }
  double selectedYaw() const;
  double observedYaw() const { return observed_yaw_; }
  const PolicyLibrary& library() const { return *library_; }

 private:
  std::shared_ptr<const PolicyLibrary> library_;
  std::vector<TvlgPolicy> locals_;
  std::vector<double> yaws_;
  ObjectGeometry object_;
  std::string path_;
  int rotation_index_ = -1;  // first entry of the object's rotation vector in x
  int selected_ = -1;
  double observed_yaw_ = 0;
};

}  // namespace adroit
