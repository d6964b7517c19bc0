#include "adroit_teleop/calibration.h"

#include <adroit_core/model_tables.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <set>

namespace adroit::teleop {

namespace {

std::string fmt(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", x);
  return buf;
}

std::string rangeText(const JointRange& r) { return "[" + fmt(r.lo) + ", " + fmt(r.hi) + "]"; }

}  // namespace

// --- GloveCalibration ----------------------------------------------------------------------

GloveCalibration::GloveCalibration(int sensors, std::vector<std::string> names, std::vector<JointRange> ranges)
    : sensors_(sensors), names_(std::move(names)), ranges_(std::move(ranges)) {
  if (sensors_ < 1) throw CalibrationError("calibration: sensor count must be >= 1, got " + std::to_string(sensors_));
  if (names_.size() != ranges_.size())
    throw CalibrationError("calibration: " + std::to_string(names_.size()) + " joint names but " +
                           std::to_string(ranges_.size()) + " ranges");
  std::set<std::string> seen;
  for (std::size_t j = 0; j < names_.size(); ++j) {
    if (!seen.insert(names_[j]).second) throw CalibrationError("calibration: joint '" + names_[j] + "' listed twice");
    const JointRange& r = ranges_[j];
    if (!std::isfinite(r.lo) || !std::isfinite(r.hi) || r.lo > r.hi)
      throw CalibrationError("calibration: joint '" + names_[j] + "' has an invalid range " + rangeText(r));
  }
  W_ = Eigen::MatrixXd::Zero(joints(), sensors_);
  b_.resize(joints());
  for (int j = 0; j < joints(); ++j) b_[j] = std::clamp(0.0, ranges_[j].lo, ranges_[j].hi);
  residual_rms = Eigen::VectorXd::Zero(joints());
  fit_samples.assign(joints(), 0);
}

void GloveCalibration::setMap(const Eigen::MatrixXd& W, const Eigen::VectorXd& b) {
  if (W.rows() != joints() || W.cols() != sensors_ || b.size() != joints())
    throw CalibrationError("calibration: map must be " + std::to_string(joints()) + " x " + std::to_string(sensors_) +
                           " with " + std::to_string(joints()) + " offsets");
  if (!W.allFinite() || !b.allFinite()) throw CalibrationError("calibration: map has non-finite entries");
  W_ = W;
  b_ = b;
}

void GloveCalibration::apply(const Eigen::Ref<const Eigen::VectorXd>& s, Eigen::Ref<Eigen::VectorXd> q) const {
  q.noalias() = W_ * s;
  q += b_;
  for (int j = 0; j < joints(); ++j) q[j] = std::clamp(q[j], ranges_[j].lo, ranges_[j].hi);
}

Eigen::VectorXd GloveCalibration::apply(const Eigen::VectorXd& s) const {
  Eigen::VectorXd q(joints());
  apply(s, q);
  return q;
}

// --- fitting -------------------------------------------------------------------------------

GloveCalibration fitCalibration(int sensors, const std::vector<std::string>& joints,
                                const std::vector<JointRange>& ranges, const std::vector<CalibrationSample>& samples,
                                double lambda) {
  GloveCalibration cal(sensors, joints, ranges);
  const int J = cal.joints();
  if (!(lambda >= 0) || !std::isfinite(lambda))
    throw CalibrationError("calibration fit: lambda must be >= 0, got " + fmt(lambda));
  for (std::size_t k = 0; k < samples.size(); ++k) {
    const CalibrationSample& x = samples[k];
    const std::string where = "calibration fit: sample " + std::to_string(k) + ": ";
    if (x.sensors.size() != sensors)
      throw CalibrationError(where + std::to_string(x.sensors.size()) + " sensor values, expected " + std::to_string(sensors));
    if (x.joints.size() != J)
      throw CalibrationError(where + std::to_string(x.joints.size()) + " joint values, expected " + std::to_string(J));
    if (!x.constrained.empty() && static_cast<int>(x.constrained.size()) != J)
      throw CalibrationError(where + "mask has " + std::to_string(x.constrained.size()) + " entries, expected " +
                             std::to_string(J));
    if (!x.sensors.allFinite() || !x.joints.allFinite()) throw CalibrationError(where + "non-finite value");
  }

  Eigen::MatrixXd W = Eigen::MatrixXd::Zero(J, sensors);
  Eigen::VectorXd b = cal.b();
  std::vector<int> used;
  for (int j = 0; j < J; ++j) {
    used.clear();
    for (std::size_t k = 0; k < samples.size(); ++k)
      if (samples[k].constrained.empty() || samples[k].constrained[j]) used.push_back(static_cast<int>(k));
    cal.fit_samples[j] = static_cast<int>(used.size());
    if (used.empty()) continue;  // nothing known about this joint: keep the default
    const double K = static_cast<double>(used.size());
    Eigen::VectorXd mean_s = Eigen::VectorXd::Zero(sensors);
    double mean_q = 0;
    for (int k : used) {
      mean_s += samples[k].sensors;
      mean_q += samples[k].joints[j];
    }
    mean_s /= K;
    mean_q /= K;
    Eigen::MatrixXd A = lambda * Eigen::MatrixXd::Identity(sensors, sensors);
    Eigen::VectorXd c = Eigen::VectorXd::Zero(sensors);
    for (int k : used) {
      const Eigen::VectorXd d = samples[k].sensors - mean_s;
      A.noalias() += d * d.transpose() / K;
      c += d * (samples[k].joints[j] - mean_q) / K;
    }
    Eigen::VectorXd w;
    if (lambda > 0) {
      w = A.ldlt().solve(c);  // A is symmetric positive definite
    } else {
      const Eigen::FullPivLU<Eigen::MatrixXd> lu(A);
      if (lu.rank() < sensors)
        throw CalibrationError("calibration fit: joint '" + joints[j] + "': the samples do not span all " +
                               std::to_string(sensors) + " sensors; use lambda > 0");
      w = lu.solve(c);
    }
    W.row(j) = w.transpose();
    b[j] = mean_q - w.dot(mean_s);
  }
  cal.setMap(W, b);
  cal.lambda = lambda;

  // Residuals of the map as teleoperation will use it (clamped).
  Eigen::VectorXd sum_sq = Eigen::VectorXd::Zero(J), q(J);
  for (const CalibrationSample& x : samples) {
    cal.apply(x.sensors, q);
    for (int j = 0; j < J; ++j)
      if (x.constrained.empty() || x.constrained[j]) sum_sq[j] += (q[j] - x.joints[j]) * (q[j] - x.joints[j]);
  }
  for (int j = 0; j < J; ++j)
    cal.residual_rms[j] = cal.fit_samples[j] > 0 ? std::sqrt(sum_sq[j] / cal.fit_samples[j]) : 0.0;
  return cal;
}

// --- YAML file -----------------------------------------------------------------------------

namespace {

// Reads fields of one YAML map and turns every problem into "<path>: <field>: <problem>".
class Reader {
 public:
  explicit Reader(std::string path) : path_(std::move(path)) {}

  [[noreturn]] void fail(const std::string& field, const std::string& problem) const {
    throw CalibrationError(path_ + ": " + field + ": " + problem);
  }
  [[noreturn]] void fail(const std::string& problem) const { throw CalibrationError(path_ + ": " + problem); }

  YAML::Node load() const { return parse(readCalibrationText(path_)); }

  YAML::Node parse(const std::string& text) const {
    YAML::Node root;
    try {
      root = YAML::Load(text);
    } catch (const YAML::Exception& e) {
      fail(std::string("not valid YAML: ") + e.what());
    }
    if (!root.IsMap()) fail("expected a map of keys");
    return root;
  }

  void onlyKeys(const YAML::Node& map, const std::set<std::string>& allowed, const std::string& prefix) const {
    for (const auto& kv : map) {
      const std::string key = kv.first.as<std::string>();
      if (!allowed.count(key)) fail(prefix + key, "unknown key");
    }
  }

  YAML::Node required(const YAML::Node& map, const std::string& key, const std::string& field) const {
    const YAML::Node v = map[key];
    if (!v) fail(field, "missing");
    return v;
  }

  double number(const YAML::Node& v, const std::string& field) const {
    double x = 0;
    if (!v.IsScalar()) fail(field, "expected a number");
    try {
      x = v.as<double>();
    } catch (const YAML::Exception&) {
      fail(field, "expected a number, got '" + v.Scalar() + "'");
    }
    if (!std::isfinite(x)) fail(field, "not finite");
    return x;
  }

  int integer(const YAML::Node& v, const std::string& field) const {
    int x = 0;
    if (!v.IsScalar()) fail(field, "expected an integer");
    try {
      x = v.as<int>();
    } catch (const YAML::Exception&) {
      fail(field, "expected an integer, got '" + v.Scalar() + "'");
    }
    return x;
  }

  std::string text(const YAML::Node& v, const std::string& field) const {
    if (!v.IsScalar()) fail(field, "expected a string");
    return v.Scalar();
  }

  YAML::Node sequence(const YAML::Node& v, const std::string& field, std::size_t size) const {
    if (!v.IsSequence()) fail(field, "expected a list of " + std::to_string(size));
    if (v.size() != size) fail(field, "expected " + std::to_string(size) + " entries, got " + std::to_string(v.size()));
    return v;
  }

  std::vector<std::string> names(const YAML::Node& v, const std::string& field) const {
    if (!v.IsSequence() || v.size() == 0) fail(field, "expected a non-empty list of joint names");
    std::vector<std::string> out;
    std::set<std::string> seen;
    for (std::size_t i = 0; i < v.size(); ++i) {
      out.push_back(text(v[i], field + "[" + std::to_string(i) + "]"));
      if (!seen.insert(out.back()).second) fail(field, "joint '" + out.back() + "' listed twice");
    }
    return out;
  }

  // The version must be there and be the one this build reads.
  void version(const YAML::Node& root, int expected) const {
    const int v = integer(required(root, "version", "version"), "version");
    if (v != expected)
      fail("version", "unknown version " + std::to_string(v) + " (this build reads " + std::to_string(expected) + ")");
  }

  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

void writeFileAtomically(const std::string& path, const std::string& text) {
  const std::string tmp = path + ".tmp" + std::to_string(getpid());
  {
    std::ofstream out(tmp, std::ios::trunc);
    if (!out) throw CalibrationError(path + ": cannot write: " + std::strerror(errno));
    out << text;
    out.flush();
    if (!out) {
      std::remove(tmp.c_str());
      throw CalibrationError(path + ": cannot write: " + std::strerror(errno));
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    std::remove(tmp.c_str());
    throw CalibrationError(path + ": cannot write: " + std::strerror(err));
  }
}

template <typename Vector>
void emitRow(YAML::Emitter& out, const Vector& v) {
  out << YAML::Flow << YAML::BeginSeq;
  for (Eigen::Index i = 0; i < v.size(); ++i) out << v[i];
  out << YAML::EndSeq;
}

}  // namespace

void saveCalibration(const std::string& path, const GloveCalibration& cal) {
  YAML::Emitter out;
  out.SetDoublePrecision(17);  // enough digits that every double reads back exactly
  out << YAML::BeginMap;
  out << YAML::Key << "version" << YAML::Value << kCalibrationFormatVersion;
  out << YAML::Key << "created" << YAML::Value << YAML::DoubleQuoted << cal.created;
  out << YAML::Key << "note" << YAML::Value << YAML::DoubleQuoted << cal.note;
  out << YAML::Key << "sensors" << YAML::Value << cal.sensors();
  out << YAML::Key << "lambda" << YAML::Value << cal.lambda;
  out << YAML::Key << "joints" << YAML::Value << YAML::Flow << cal.jointNames();
  out << YAML::Key << "ranges" << YAML::Value << YAML::BeginSeq;
  for (const JointRange& r : cal.ranges()) emitRow(out, Eigen::Vector2d(r.lo, r.hi));
  out << YAML::EndSeq;
  out << YAML::Key << "W" << YAML::Value << YAML::BeginSeq;
  for (int j = 0; j < cal.joints(); ++j) emitRow(out, Eigen::VectorXd(cal.W().row(j).transpose()));
  out << YAML::EndSeq;
  out << YAML::Key << "b" << YAML::Value;
  emitRow(out, cal.b());
  out << YAML::Key << "residual_rms" << YAML::Value;
  emitRow(out, cal.residual_rms);
  out << YAML::Key << "fit_samples" << YAML::Value << YAML::Flow << cal.fit_samples;
  out << YAML::EndMap;
  if (!out.good()) throw CalibrationError(path + ": cannot write: " + out.GetLastError());
  writeFileAtomically(path, std::string("# ADROIT glove calibration: q = clamp(W s + b), s = raw sensor / 255\n") +
                                out.c_str() + "\n");
}

std::string readCalibrationText(const std::string& path) {
  try {
    return readBoundedFile(path, kMaxCalibrationFileBytes);
  } catch (const FileError& e) {  // "<path>: <why>"
    throw CalibrationError(e.what());
  }
}

GloveCalibration loadCalibration(const std::string& path) { return parseCalibration(path, readCalibrationText(path)); }

GloveCalibration parseCalibration(const std::string& path, const std::string& text) {
  const Reader r(path);
  const YAML::Node root = r.parse(text);
  r.version(root, kCalibrationFormatVersion);
  r.onlyKeys(root, {"version", "created", "note", "sensors", "lambda", "joints", "ranges", "W", "b", "residual_rms",
                    "fit_samples"},
             "");
  const int N = r.integer(r.required(root, "sensors", "sensors"), "sensors");
  if (N < 1) r.fail("sensors", "must be >= 1, got " + std::to_string(N));
  const std::vector<std::string> names = r.names(r.required(root, "joints", "joints"), "joints");
  const std::size_t J = names.size();

  std::vector<JointRange> ranges;
  const YAML::Node rn = r.sequence(r.required(root, "ranges", "ranges"), "ranges", J);
  for (std::size_t j = 0; j < J; ++j) {
    const std::string field = "ranges[" + std::to_string(j) + "]";
    const YAML::Node pair = r.sequence(rn[j], field, 2);
    const JointRange range{r.number(pair[0], field + "[0]"), r.number(pair[1], field + "[1]")};
    if (range.lo > range.hi) r.fail(field, "lower limit above upper limit");
    ranges.push_back(range);
  }

  Eigen::MatrixXd W(J, N);
  const YAML::Node wn = r.sequence(r.required(root, "W", "W"), "W", J);
  for (std::size_t j = 0; j < J; ++j) {
    const std::string field = "W[" + std::to_string(j) + "]";
    const YAML::Node row = r.sequence(wn[j], field, N);
    for (int i = 0; i < N; ++i) W(j, i) = r.number(row[i], field + "[" + std::to_string(i) + "]");
  }
  auto vector = [&](const std::string& key) {
    Eigen::VectorXd v(J);
    const YAML::Node n = r.sequence(r.required(root, key, key), key, J);
    for (std::size_t j = 0; j < J; ++j) v[j] = r.number(n[j], key + "[" + std::to_string(j) + "]");
    return v;
  };
  const Eigen::VectorXd b = vector("b");
  const Eigen::VectorXd residual = vector("residual_rms");
  if ((residual.array() < 0).any()) r.fail("residual_rms", "negative entry");

  std::vector<int> fit_samples;
  const YAML::Node fn = r.sequence(r.required(root, "fit_samples", "fit_samples"), "fit_samples", J);
  for (std::size_t j = 0; j < J; ++j) {
    fit_samples.push_back(r.integer(fn[j], "fit_samples[" + std::to_string(j) + "]"));
    if (fit_samples.back() < 0) r.fail("fit_samples[" + std::to_string(j) + "]", "negative");
  }

  const double lambda = r.number(r.required(root, "lambda", "lambda"), "lambda");
  if (lambda < 0) r.fail("lambda", "negative");

  GloveCalibration cal;
  try {
    cal = GloveCalibration(N, names, ranges);
  } catch (const CalibrationError& e) {
    r.fail(e.what());
  }
  cal.setMap(W, b);
  cal.residual_rms = residual;
  cal.fit_samples = fit_samples;
  cal.lambda = lambda;
  cal.created = r.text(r.required(root, "created", "created"), "created");
  if (const YAML::Node note = root["note"]) cal.note = r.text(note, "note");
  return cal;
}

// --- calibration poses ---------------------------------------------------------------------

CalibrationPoseSet loadCalibrationPoses(const std::string& path, const std::map<std::string, JointRange>& known) {
  const Reader r(path);
  const YAML::Node root = r.load();
  r.version(root, 1);
  r.onlyKeys(root, {"version", "description", "joints", "poses"}, "");

  CalibrationPoseSet set;
  set.joints = r.names(r.required(root, "joints", "joints"), "joints");
  std::map<std::string, int> index;
  for (const std::string& name : set.joints) {
    const auto it = known.find(name);
    if (it == known.end()) r.fail("joints", "unknown joint '" + name + "' (not a limited joint of the model)");
    index[name] = static_cast<int>(set.ranges.size());
    set.ranges.push_back(it->second);
  }
  const int J = static_cast<int>(set.joints.size());

  const YAML::Node poses = r.required(root, "poses", "poses");
  if (!poses.IsSequence() || poses.size() == 0) r.fail("poses", "expected a non-empty list of poses");
  std::set<std::string> pose_names;
  for (std::size_t p = 0; p < poses.size(); ++p) {
    const YAML::Node node = poses[p];
    std::string where = "poses[" + std::to_string(p) + "]";
    if (!node.IsMap()) r.fail(where, "expected a map with name, instruction, targets, free");
    CalibrationPose pose;
    pose.name = r.text(r.required(node, "name", where + ".name"), where + ".name");
    where += " (" + pose.name + ")";
    if (!pose_names.insert(pose.name).second) r.fail(where, "pose name used twice");
    r.onlyKeys(node, {"name", "instruction", "targets", "free"}, where + ".");
    if (const YAML::Node text = node["instruction"]) pose.instruction = r.text(text, where + ".instruction");
    pose.targets = Eigen::VectorXd::Zero(J);
    pose.constrained.assign(J, true);
    std::vector<bool> listed(J, false);

    const YAML::Node targets = r.required(node, "targets", where + ".targets");
    if (!targets.IsMap() && !(targets.IsNull())) r.fail(where + ".targets", "expected a map of joint name: angle (rad)");
    for (const auto& kv : targets) {
      const std::string name = kv.first.as<std::string>();
      const std::string field = where + ".targets." + name;
      const auto it = index.find(name);
      if (it == index.end())
        r.fail(field, known.count(name) ? "joint '" + name + "' is not in the pose set's joints"
                                        : "unknown joint '" + name + "'");
      const double q = r.number(kv.second, field);
      const JointRange& range = set.ranges[it->second];
      if (q < range.lo || q > range.hi) r.fail(field, fmt(q) + " is outside the joint's range " + rangeText(range));
      pose.targets[it->second] = q;
      listed[it->second] = true;
    }
    if (const YAML::Node free = node["free"]) {
      if (!free.IsSequence()) r.fail(where + ".free", "expected a list of joint names");
      for (std::size_t i = 0; i < free.size(); ++i) {
        const std::string name = r.text(free[i], where + ".free[" + std::to_string(i) + "]");
        const auto it = index.find(name);
        if (it == index.end()) r.fail(where + ".free", "unknown joint '" + name + "'");
        if (listed[it->second]) r.fail(where + ".free", "joint '" + name + "' also has a target");
        pose.constrained[it->second] = false;
      }
    }
    // An unlisted joint's target is 0, which must be a reachable angle.
    for (int j = 0; j < J; ++j) {
      const JointRange& range = set.ranges[j];
      if (!listed[j] && pose.constrained[j] && (0 < range.lo || 0 > range.hi))
        r.fail(where, "joint '" + set.joints[j] + "' is not listed and 0 is outside its range " + rangeText(range));
    }
    set.poses.push_back(std::move(pose));
  }
  return set;
}

CalibrationSample poseSample(const CalibrationPose& pose, const Eigen::VectorXd& sensors) {
  return CalibrationSample{sensors, pose.targets, pose.constrained};
}

std::map<std::string, JointRange> jointRangesFromModel(const mjModel* model) {
  std::map<std::string, JointRange> ranges;
  const NameIndex joints(model, mjOBJ_JOINT);
  for (int j = 0; j < model->njnt; ++j) {
    const int type = model->jnt_type[j];
    if ((type != mjJNT_HINGE && type != mjJNT_SLIDE) || !model->jnt_limited[j]) continue;
    const std::string& name = joints.name(j);
    if (name.empty()) continue;
    ranges[name] = {model->jnt_range[2 * j], model->jnt_range[2 * j + 1]};
  }
  return ranges;
}

}  // namespace adroit::teleop
