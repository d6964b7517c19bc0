// Glove-to-joint calibration (thesis 10.3: "a regression based calibration process, that maps
// the Cyberglove sensors to the ADROIT joint space"): an affine map q = W s + b from the N
// sensor values (raw / 255, see glove_protocol.h) to J joint angles (rad), clamped to each
// joint's range; fitted by ridge regression from samples taken while the user holds known
// poses; saved to and loaded from a versioned YAML file.
#pragma once

#include <adroit_core/bounded_file.h>
#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace adroit::teleop {

constexpr int kCalibrationFormatVersion = 1;
// Default ridge weight. Sensor values are in (0, 1]. A pose change moves a sensor's value
// with a variance of about 1e-2, one-step sensor noise has (1/255)^2 ~ 1.5e-5. With 1e-4 a
// weight along a direction the poses moved shrinks by only ~1 % (lambda / (variance +
// lambda)), while directions the poses never moved (only noise there) are damped towards 0
// instead of being fitted to the noise.
constexpr double kDefaultRidgeLambda = 1e-4;
// The largest calibration or pose file read. A 22-sensor calibration of a 30-joint hand is
// about 15 kB (W alone is 660 doubles written exactly) and the pose file a few kB: 1 MiB is
// far above any real file, and a wrong path (a log, a device, a bag) is refused unread.
constexpr std::size_t kMaxCalibrationFileBytes = 1 * kMiB;

class CalibrationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct JointRange {
  double lo = 0, hi = 0;
};

// One observation: the glove's sensor values while the hand held `joints`. `constrained[j]`
// says whether this sample says anything about joint j (empty = every joint): a pose that
// only concerns the thumb does not have to pin the wrist.
struct CalibrationSample {
  Eigen::VectorXd sensors;
  Eigen::VectorXd joints;
  std::vector<bool> constrained;
};

class GloveCalibration {
 public:
  GloveCalibration() = default;
  // The default map: W = 0, b = 0 clamped into each range (every joint at rest). Throws CalibrationError
  // for sensors < 1, names/ranges of different lengths, duplicate names, or lo > hi.
  GloveCalibration(int sensors, std::vector<std::string> joints, std::vector<JointRange> ranges);

  int sensors() const { return sensors_; }
  int joints() const { return static_cast<int>(names_.size()); }
  const std::vector<std::string>& jointNames() const { return names_; }
  const std::vector<JointRange>& ranges() const { return ranges_; }
  const Eigen::MatrixXd& W() const { return W_; }  // J x N
  const Eigen::VectorXd& b() const { return b_; }  // J

  // Replaces the map; throws CalibrationError for wrong sizes or non-finite entries.
  void setMap(const Eigen::MatrixXd& W, const Eigen::VectorXd& b);

  // q = clamp(W s + b, lo, hi). s has sensors() entries, q joints(); allocates nothing.
  void apply(const Eigen::Ref<const Eigen::VectorXd>& s, Eigen::Ref<Eigen::VectorXd> q) const;
  Eigen::VectorXd apply(const Eigen::VectorXd& s) const;

  // Filled by fitCalibration (and kept by save/load):
  Eigen::VectorXd residual_rms;  // per joint: RMS of apply(s) - target over its samples (rad)
  std::vector<int> fit_samples;  // per joint: samples that constrained it (0 = default kept)
  double lambda = 0;             // ridge weight used
  std::string created;           // UTC, ISO 8601 ("2024-05-01T12:00:00Z")
  std::string note;              // free text: who, which glove, which pose file...

 private:
  int sensors_ = 0;
  std::vector<std::string> names_;
  std::vector<JointRange> ranges_;
  Eigen::MatrixXd W_;
  Eigen::VectorXd b_;
};

// Fits each joint j separately on the samples that constrain it:
//   minimise  (1/K_j) sum_k (w_j . s_k + b_j - q_kj)^2 + lambda |w_j|^2
// (b_j not regularised, so a constant offset costs nothing). Solved on centred data:
// w_j = (C + lambda I)^-1 c_j with C the sensor covariance and c_j the sensor-joint
// covariance, b_j = mean(q_j) - w_j . mean(s). Dividing by K_j keeps lambda's meaning
// independent of how long the poses were held. A joint no sample constrains keeps the
// default (zero row, b = 0 clamped into its range) and fit_samples[j] = 0.
// Throws CalibrationError for samples of the wrong size, non-finite values, lambda < 0,
// or lambda == 0 with too few samples to determine a joint.
GloveCalibration fitCalibration(int sensors, const std::vector<std::string>& joints,
                                const std::vector<JointRange>& ranges, const std::vector<CalibrationSample>& samples,
                                double lambda = kDefaultRidgeLambda);

// YAML file (version, sensors, joints, ranges, W, b, residual_rms, fit_samples, lambda, created,
// note), written atomically (temporary file + rename) with every double exact.
// Throws CalibrationError "<path>: ..." when it cannot be written.
void saveCalibration(const std::string& path, const GloveCalibration& calibration);
// Validates everything (missing or unknown keys, sizes, non-finite numbers, version, ranges);
// throws CalibrationError whose message starts with "<path>: " and names the key.
// The file must be a regular file of at most kMaxCalibrationFileBytes (readCalibrationText).
GloveCalibration loadCalibration(const std::string& path);
// The text of a calibration or pose file: a regular file (a FIFO, a device or a directory is
// refused without reading, so this never blocks) of at most kMaxCalibrationFileBytes. Throws
// CalibrationError "<path>: not a regular file (a FIFO)", "<path>: 2 MB, over the limit of 1 MB".
std::string readCalibrationText(const std::string& path);
// loadCalibration on a text already read (readCalibrationText); `path` names it in errors.
GloveCalibration parseCalibration(const std::string& path, const std::string& text);

// --- calibration poses -----------------------------------------------------------------------

// A pose the user is asked to hold. `targets` has one entry per joint of the pose set (joints
// the file does not list are 0); `constrained[j]` is false for the joints the pose lists as
// free (the pose says nothing about them).
struct CalibrationPose {
  std::string name, instruction;
  Eigen::VectorXd targets;
  std::vector<bool> constrained;
};

struct CalibrationPoseSet {
  std::vector<std::string> joints;  // the joints the calibration maps to, in order
  std::vector<JointRange> ranges;   // of those joints, from `known`
  std::vector<CalibrationPose> poses;
};

// Loads a pose file (config/calibration_poses.yaml). `known` holds the model's joints and
// ranges (jointRangesFromModel): every joint the file names must be among them and every
// target inside its range. Throws CalibrationError "<path>: <where>: <what>".
CalibrationPoseSet loadCalibrationPoses(const std::string& path, const std::map<std::string, JointRange>& known);

// A sample from a pose and the sensor values recorded while it was held.
CalibrationSample poseSample(const CalibrationPose& pose, const Eigen::VectorXd& sensors);

// Name -> range of every limited hinge or slide joint of a MuJoCo model.
std::map<std::string, JointRange> jointRangesFromModel(const mjModel* model);

}  // namespace adroit::teleop
