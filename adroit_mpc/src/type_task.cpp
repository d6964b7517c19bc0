#include "adroit_mpc/type_task.h"

#include <adroit_core/mujoco_model.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

namespace adroit_mpc {

namespace {

const std::string kTask = "type";

struct TypeScratch : TaskScratch {
  TypeScratch(const mjModel* m, int nkeys)
      : buf(m, std::max(6, m->nv)), key_targets(nkeys, 0.0), key_scales(nkeys, 0.0) {}
  ResidualBuffer buf;
  std::vector<double> key_targets, key_scales;
};

TypeScratch& scratchOf(TaskScratch& s) {
  auto* scratch = dynamic_cast<TypeScratch*>(&s);
  if (!scratch) throw std::invalid_argument("task type: scratch was not made by this task");
  return *scratch;
}

int fingerIndex(const std::string& name) {
  const auto& names = TypeTask::fingerNames();
  for (int f = 0; f < 5; ++f)
    if (name == names[f]) return f;
  return -1;
}

// "1:ff, 0:th" -> {("1", 0), ("0", 4)}; label existence is checked in bind().
std::vector<std::pair<std::string, int>> parseAssignment(const std::string& text) {
  std::vector<std::pair<std::string, int>> out;
  std::string item;
  std::istringstream stream(text);
  while (std::getline(stream, item, ',')) {
    item.erase(std::remove_if(item.begin(), item.end(), [](unsigned char c) { return std::isspace(c); }),
               item.end());
    if (item.empty()) continue;
    const auto colon = item.find(':');
    const int finger = colon == std::string::npos ? -1 : fingerIndex(item.substr(colon + 1));
    if (colon == std::string::npos || colon == 0 || finger < 0)
      throw std::invalid_argument("task type: parameter 'finger_assignment': bad entry '" + item +
                                  "' (expected <key label>:<ff|mf|rf|lf|th>)");
    out.emplace_back(item.substr(0, colon), finger);
  }
  return out;
}

}  // namespace

void approachFromAbove(double height, double radius, ResidualBuffer& buf) {
  if (!(height > 0) || !(radius > 0)) return;
  const double rho2 = buf.r[0] * buf.r[0] + buf.r[1] * buf.r[1], a2 = radius * radius;
  buf.r[2] -= height * rho2 / (rho2 + a2);
  if (!buf.uses_q) return;
  // d lift / d r_xy = height * a2 / (rho2 + a2)^2 * 2 r_xy
  const double slope = 2.0 * height * a2 / ((rho2 + a2) * (rho2 + a2));
  buf.jq.row(2) -= slope * (buf.r[0] * buf.jq.row(0) + buf.r[1] * buf.jq.row(1));
}

const std::array<const char*, 5>& TypeTask::fingerNames() {
  static const std::array<const char*, 5> names = {"ff", "mf", "rf", "lf", "th"};
  return names;
}

const std::array<const char*, 5>& TypeTask::fingertipSites() {
  static const std::array<const char*, 5> sites = {"S_fftip", "S_mftip", "S_rftip", "S_lftip", "S_thtip"};
  return sites;
}

TaskParams TypeTask::defaults() {
  TaskParams p;
  p.strings = {{"scene", "keypad"}, {"sequence", ""}, {"finger_assignment", ""}, {"assignment_keyframe", "rest"}};
  p.numbers = {{"w_press", 1.0},        {"w_approach", 20.0},       {"w_hover", 5.0},
               {"w_other_keys", 5.0},    {"w_posture", 0.1},         {"w_control", 0.1},
               {"w_synergy", 0.08},      {"terminal_scale", 5.0},    {"hover_height", 0.0225},
               {"approach_smoothing", 0.005}, {"key_period", 0.25}, {"min_lead", 1.0},
               {"step_smoothness", 0.03}, {"release_depth", 0.0035}, {"horizon", 0.2},
               {"planner_dt", 0.01},      {"derivative_skip", 3},    {"feedback_scale", 0.5},
               {"latency_compensation", 1}, {"approach_radius", 0.004}};
  return p;
}

TypeTask::TypeTask(const TaskParams& params) {
  const TaskParams p = mergeTaskParams(kTask, defaults(), params);
  weights_ = WeightTable(kTask, p);
  w_press_ = weights_.index("w_press");
  w_approach_ = weights_.index("w_approach");
  w_hover_ = weights_.index("w_hover");
  w_other_keys_ = weights_.index("w_other_keys");
  w_posture_ = weights_.index("w_posture");
  w_control_ = weights_.index("w_control");
  w_synergy_ = weights_.index("w_synergy");
  terminal_scale_ = paramNumber(kTask, p, "terminal_scale", 0, 1e6);
  hover_height_ = paramNumber(kTask, p, "hover_height", 0, 0.2);
  approach_smoothing_ = paramNumber(kTask, p, "approach_smoothing", 1e-6, 1);
  key_period_ = paramNumber(kTask, p, "key_period", 1e-3, 10);
  min_lead_ = paramNumber(kTask, p, "min_lead", 0, 10);
  step_smoothness_ = paramNumber(kTask, p, "step_smoothness", 1e-4, 10);
  release_depth_ = paramNumber(kTask, p, "release_depth", 0, 0.1);
  approach_radius_ = paramNumber(kTask, p, "approach_radius", 0, 0.1);
  horizon_hint_ = paramNumber(kTask, p, "horizon", 1e-3, 10);
  planner_dt_hint_ = paramNumber(kTask, p, "planner_dt", 1e-4, 1);
  paramNumber(kTask, p, "derivative_skip", 1, 100);  // planner hints, read by their users
  paramNumber(kTask, p, "feedback_scale", 0, 1);
  paramNumber(kTask, p, "latency_compensation", 0, 1);
  paramString(kTask, p, "scene");
  assignment_keyframe_ = paramString(kTask, p, "assignment_keyframe");
  assignment_overrides_ = parseAssignment(paramString(kTask, p, "finger_assignment"));
  digit_key_.fill(kNoKey);
  std::string why;
  if (!setSequence(paramString(kTask, p, "sequence"), &why))
    throw std::invalid_argument("task type: parameter 'sequence': " + why);
}

void TypeTask::copyParametersFrom(const Task& other) {
  const auto* source = dynamic_cast<const TypeTask*>(&other);
  if (!source) throw std::invalid_argument("task type: cannot copy the parameters of task " + other.name());
  weights_.copyValuesFrom(source->weights_);
  sequence_ = source->sequence_;
  sequence_length_ = source->sequence_length_;
  matched_ = source->matched_;
  wrong_ = source->wrong_;
  presses_ = source->presses_;
  wrong_presses_ = source->wrong_presses_;
  held_ = source->held_;
  t_event_ = source->t_event_;
  t_observed_ = source->t_observed_;
}

void TypeTask::bind(const mjModel* model, int synergy_dims) {
  // Keys: every slide joint KEY_<label>, its body and the box geom on it.
  labels_.clear();
  std::vector<std::string> joint_names;
  for (int j = 0; j < model->njnt; ++j) {
    const char* name = mj_id2name(model, mjOBJ_JOINT, j);
    if (name && std::string(name).rfind("KEY_", 0) == 0 && model->jnt_type[j] == mjJNT_SLIDE) {
      joint_names.emplace_back(name);
      labels_.emplace_back(name + 4);
    }
  }
  if (labels_.empty()) throw std::invalid_argument("task type: the model has no key joints KEY_<label> (scene keypad)");
  if (static_cast<int>(labels_.size()) > kMaxKeys)
    throw std::invalid_argument("task type: the model has " + std::to_string(labels_.size()) + " keys, at most " +
                                std::to_string(kMaxKeys) + " are supported");
  const int depth_id = mj_name2id(model, mjOBJ_NUMERIC, "keypad_press_depth");
  if (depth_id < 0) throw std::invalid_argument("task type: the model has no custom numeric 'keypad_press_depth'");
  press_depth_ = model->numeric_data[model->numeric_adr[depth_id]];
  if (!(release_depth_ < press_depth_))
    throw std::invalid_argument("task type: parameter 'release_depth' (" + std::to_string(release_depth_) +
                                ") must be below the press depth " + std::to_string(press_depth_));
  nkeys_ = static_cast<int>(labels_.size());
  key_joints_ = JointList::named(model, joint_names);

  const int keyframe = mj_name2id(model, mjOBJ_KEY, assignment_keyframe_.c_str());
  if (keyframe < 0)
    throw std::invalid_argument("task type: the model has no keyframe '" + assignment_keyframe_ +
                                "' (parameter assignment_keyframe)");
  for (int f = 0; f < 5; ++f) {
    try {
      fingertips_[f] = BodyPoint::site(model, fingertipSites()[f]);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(std::string("task type: ") + e.what());
    }
  }
  // Key geometry at the keyframe: world positions of the key tops and the fingertips.
  adroit::DataPtr data = adroit::makeData(model);
  mju_copy(data->qpos, model->key_qpos + keyframe * model->nq, model->nq);
  mj_kinematics(model, data.get());
  key_travel_.assign(nkeys_, 0.0);
  key_tops_.assign(nkeys_, BodyPoint{});
  key_hovers_.assign(nkeys_, BodyPoint{});
  std::vector<Eigen::Vector3d> top_world(nkeys_);
  for (int k = 0; k < nkeys_; ++k) {
    const int joint = key_joints_.joint[k];
    const int body = model->jnt_bodyid[joint];
    key_travel_[k] = -model->jnt_range[2 * joint];
    if (!(key_travel_[k] > 0))
      throw std::invalid_argument("task type: key joint KEY_" + labels_[k] + " has no downward travel");
    int geom = -1;
    for (int g = 0; g < model->ngeom && geom < 0; ++g)
      if (model->geom_bodyid[g] == body && model->geom_type[g] == mjGEOM_BOX) geom = g;
    if (geom < 0) throw std::invalid_argument("task type: key " + labels_[k] + " has no box geom");
    const Eigen::Vector3d top =
        Eigen::Vector3d(model->geom_pos + 3 * geom) + Eigen::Vector3d(0, 0, model->geom_size[3 * geom + 2]);
    key_tops_[k] = BodyPoint{body, top};
    // Joint at 0 (key up) for the hover point, whatever the keyframe holds.
    top_world[k] = key_tops_[k].position(data.get()) -
                   Eigen::Vector3d(0, 0, data->qpos[key_joints_.qpos_adr[k]]);
    key_hovers_[k] = BodyPoint::world(top_world[k] + Eigen::Vector3d(0, 0, hover_height_));
  }

  // Heat map: group keys into columns by their x, give every column a different finger,
  // choosing the assignment with the least summed horizontal fingertip-to-key distance.
  std::vector<double> column_x;
  std::vector<int> key_column(nkeys_);
  for (int k = 0; k < nkeys_; ++k) {
    int c = 0;
    while (c < static_cast<int>(column_x.size()) && std::abs(column_x[c] - top_world[k].x()) > 0.005) ++c;
    if (c == static_cast<int>(column_x.size())) column_x.push_back(top_world[k].x());
    key_column[k] = c;
  }
  const int ncol = static_cast<int>(column_x.size());
  if (ncol > 5) throw std::invalid_argument("task type: the keypad has more than 5 key columns");
  std::array<Eigen::Vector3d, 5> tip;
  for (int f = 0; f < 5; ++f) tip[f] = fingertips_[f].position(data.get());
  std::vector<std::vector<double>> column_cost(ncol, std::vector<double>(5, 0.0));
  for (int k = 0; k < nkeys_; ++k)
    for (int f = 0; f < 5; ++f) column_cost[key_column[k]][f] += (top_world[k] - tip[f]).head<2>().norm();
  std::vector<int> fingers = {0, 1, 2, 3, 4}, best;
  double best_cost = std::numeric_limits<double>::infinity();
  do {  // permutations of the fingers; the first ncol entries go to the columns
    double total = 0;
    for (int c = 0; c < ncol; ++c) total += column_cost[c][fingers[c]];
    if (total < best_cost - 1e-12) {
      best_cost = total;
      best = fingers;
    }
  } while (std::next_permutation(fingers.begin(), fingers.end()));
  key_finger_.assign(nkeys_, 0);
  for (int k = 0; k < nkeys_; ++k) key_finger_[k] = best[key_column[k]];
  for (const auto& entry : assignment_overrides_) {
    const auto it = std::find(labels_.begin(), labels_.end(), entry.first);
    if (it == labels_.end())
      throw std::invalid_argument("task type: parameter 'finger_assignment': the keypad has no key '" +
                                  entry.first + "'");
    key_finger_[it - labels_.begin()] = entry.second;
  }
  // Each finger's home: its key nearest to its fingertip at the keyframe.
  home_key_.fill(kNoKey);
  for (int k = 0; k < nkeys_; ++k) {
    int& home = home_key_[key_finger_[k]];
    const Eigen::Vector3d& tip_f = tip[key_finger_[k]];
    if (home == kNoKey || (top_world[k] - tip_f).norm() < (top_world[home] - tip_f).norm()) home = k;
  }

  digit_key_.fill(kNoKey);
  backspace_key_ = kNoKey;
  for (int k = 0; k < nkeys_; ++k) {
    if (labels_[k].size() == 1 && std::isdigit(static_cast<unsigned char>(labels_[k][0])))
      digit_key_[labels_[k][0] - '0'] = k;
    if (labels_[k] == "bs") backspace_key_ = k;
  }
  if (backspace_key_ == kNoKey) throw std::invalid_argument("task type: the keypad has no backspace key 'bs'");
  for (int i = 0; i < sequence_length_; ++i)
    if (digit_key_[sequence_[i] - '0'] == kNoKey)
      throw std::invalid_argument(std::string("task type: the keypad has no key '") + sequence_[i] + "'");

  hand_joints_ = JointList::where(model, [](const std::string& n) { return n.rfind("KEY_", 0) != 0; });
  rest_targets_.resize(hand_joints_.size());
  unit_scales_.assign(hand_joints_.size(), 1.0);
  const int rest = mj_name2id(model, mjOBJ_KEY, "rest");
  for (int i = 0; i < hand_joints_.size(); ++i)
    rest_targets_[i] = rest < 0 ? model->qpos0[hand_joints_.qpos_adr[i]]
                                : model->key_qpos[rest * model->nq + hand_joints_.qpos_adr[i]];
  control_effort_.bind(model, synergy_dims);
  nx_ = 2 * model->nv + model->na;
  nu_total_ = model->nu + synergy_dims;
  bound_ = true;
}

std::unique_ptr<TaskScratch> TypeTask::makeScratch(const mjModel* model) const {
  checkBound();
  return std::make_unique<TypeScratch>(model, nkeys_);
}

void TypeTask::checkBound() const {
  if (!bound_) throw std::logic_error("task type: used before bind()");
}

int TypeTask::keyOfChar(char c) const { return digit_key_[c - '0']; }

TypeTask::Targets TypeTask::targets() const {
  Targets out;
  const bool more = matched_ < sequence_length_;
  if (wrong_ > 0) {
    out.current = backspace_key_;
    if (wrong_ > 1)
      out.next = backspace_key_;
    else if (more)
      out.next = keyOfChar(sequence_[matched_]);
  } else if (more) {
    out.current = keyOfChar(sequence_[matched_]);
    if (matched_ + 1 < sequence_length_) out.next = keyOfChar(sequence_[matched_ + 1]);
  }
  return out;
}

std::string TypeTask::currentTarget() const {
  checkBound();
  const int k = targets().current;
  return k == kNoKey ? "" : labels_[k];
}

std::string TypeTask::nextTarget() const {
  checkBound();
  const int k = targets().next;
  return k == kNoKey ? "" : labels_[k];
}

int TypeTask::fingerOfKey(const std::string& label) const {
  checkBound();
  const auto it = std::find(labels_.begin(), labels_.end(), label);
  if (it == labels_.end()) throw std::invalid_argument("task type: the keypad has no key '" + label + "'");
  return key_finger_[it - labels_.begin()];
}

SmoothStep TypeTask::currentStep() const {
  SmoothStep step;
  step.a1 = t_event_;
  step.b1 = step_smoothness_;
  step.a2 = std::max(t_event_ + key_period_, t_observed_ + min_lead_);
  step.b2 = step_smoothness_;
  return step;
}

bool TypeTask::setSequence(const std::string& keys, std::string* why) {
  if (static_cast<int>(keys.size()) > kMaxSequence) {
    *why = "sequence of " + std::to_string(keys.size()) + " keys is longer than " + std::to_string(kMaxSequence);
    return false;
  }
  for (size_t i = 0; i < keys.size(); ++i) {
    if (!std::isdigit(static_cast<unsigned char>(keys[i]))) {
      *why = "sequence '" + keys + "': '" + keys[i] + "' at position " + std::to_string(i + 1) +
             " is not a digit (the keypad types 0-9)";
      return false;
    }
    if (bound_ && digit_key_[keys[i] - '0'] == kNoKey) {
      *why = std::string("sequence '") + keys + "': the keypad has no key '" + keys[i] + "'";
      return false;
    }
  }
  std::copy(keys.begin(), keys.end(), sequence_.begin());
  sequence_length_ = static_cast<int>(keys.size());
  matched_ = 0;
  wrong_ = 0;
  presses_ = 0;
  wrong_presses_ = 0;
  t_event_ = t_observed_;
  return true;
}

std::vector<TaskEvent> TypeTask::observe(const mjModel*, const mjData* d, double t) {
  checkBound();
  std::vector<TaskEvent> events;
  t_observed_ = t;
  for (int k = 0; k < nkeys_; ++k) {
    const double q = d->qpos[key_joints_.qpos_adr[k]];
    if (held_[k]) {
      if (q > -release_depth_) held_[k] = false;  // hysteresis: up past the release level
      continue;
    }
    if (q > -press_depth_) continue;
    held_[k] = true;
    t_event_ = t;
    const Targets expected = targets();
    events.push_back({"key", labels_[k]});
    ++presses_;
    wrong_presses_ += k != expected.current;  // a backspace that removes a wrong key is expected
    if (k == expected.current) {
      if (wrong_ > 0) {
        --wrong_;
      } else {
        ++matched_;
        if (matched_ == sequence_length_) events.push_back({"done", sequence()});
      }
    } else if (k == backspace_key_ && wrong_ == 0 && matched_ > 0) {
      --matched_;
      events.push_back({"error", "backspace deleted a typed key"});
    } else if (k == backspace_key_ && wrong_ == 0) {
      // Backspace on nothing typed: nothing changes.
    } else {
      ++wrong_;
      const std::string wanted = expected.current == kNoKey ? std::string("nothing") : labels_[expected.current];
      events.push_back({"error", "pressed " + labels_[k] + " instead of " + wanted});
    }
  }
  return events;
}

double TypeTask::error(const mjModel*, const mjData*) const { return wrong_ + (sequence_length_ - matched_); }

double TypeTask::cost(const mjModel* m, const mjData* d, const Eigen::VectorXd* u, double t, TaskScratch& s,
                      CostDerivatives* out, double scale) const {
  checkBound();
  if (u && u->size() != nu_total_)
    throw std::invalid_argument("task type: control has " + std::to_string(u->size()) + " entries, expected " +
                                std::to_string(nu_total_));
  if (out && out->lx.size() != nx_)
    throw std::invalid_argument("task type: CostDerivatives has " + std::to_string(out->lx.size()) +
                                " state entries, expected " + std::to_string(nx_));
  if (out) out->setZero();
  TypeScratch& scratch = scratchOf(s);
  ResidualBuffer& buf = scratch.buf;
  const bool derivatives = out != nullptr;
  const Targets target = targets();
  const SmoothStep step = currentStep();
  const double s_up = step.up(t), s_dn = 1.0 - s_up;
  double total = 0;

  // One key towards a depth (normalised by its travel); a fingertip towards a point.
  std::fill(scratch.key_scales.begin(), scratch.key_scales.end(), 0.0);
  std::fill(scratch.key_targets.begin(), scratch.key_targets.end(), 0.0);
  auto keyTerm = [&](int k, double depth, double w) {  // depth 0 = up, travel = fully pressed
    std::fill(scratch.key_scales.begin(), scratch.key_scales.end(), 0.0);
    scratch.key_scales[k] = 1.0 / key_travel_[k];
    scratch.key_targets[k] = -depth;
    jointResidual(m, d, key_joints_, scratch.key_targets.data(), scratch.key_scales.data(), derivatives, buf);
    total += addResidualCost(scale * w, Norm::quadratic(), buf, out);
    scratch.key_targets[k] = 0.0;
  };
  auto tipTerm = [&](int k, const BodyPoint& point, double w) {
    pointResidual(m, d, fingertips_[key_finger_[k]], point, derivatives, buf);
    total += addResidualCost(scale * w, Norm::smoothAbs(approach_smoothing_), buf, out);
  };
  // A fingertip onto a key top from above: the target rises to hover_height as the tip
  // strays sideways (approachFromAbove), so the tip descends only over its key.
  auto keyApproachTerm = [&](int k, double w) {
    pointResidual(m, d, fingertips_[key_finger_[k]], key_tops_[k], derivatives, buf);
    approachFromAbove(hover_height_, approach_radius_, buf);
    total += addResidualCost(scale * w, Norm::smoothAbs(approach_smoothing_), buf, out);
  };

  if (target.current != kNoKey) {
    const int c = target.current;
    if (held_[c]) {  // still down from its last press: lift it first
      keyTerm(c, 0.0, weights_[w_press_] * s_up);
      tipTerm(c, key_hovers_[c], weights_[w_approach_] * s_up);
    } else {
      keyTerm(c, key_travel_[c], weights_[w_press_] * s_up);
      keyApproachTerm(c, weights_[w_approach_] * s_up);
    }
    if (target.next != kNoKey) {
      const int n = target.next;
      keyTerm(n, key_travel_[n], weights_[w_press_] * s_dn);
      keyApproachTerm(n, weights_[w_approach_] * s_dn);
      if (key_finger_[n] != key_finger_[c]) tipTerm(n, key_hovers_[n], weights_[w_hover_] * s_up);
    }
  }
  // Every finger with keys but no target now hovers above its home key. Resting on a key
  // top, within the contact margin, a fingertip is one sensor-noise step from contact, and
  // plans from such states jolt the hand (keys typed unasked, mpc_success --idle).
  const int current_finger = target.current != kNoKey ? key_finger_[target.current] : -1;
  const int next_finger = target.next != kNoKey ? key_finger_[target.next] : -1;
  for (int f = 0; f < 5; ++f)
    if (home_key_[f] != kNoKey && f != current_finger && f != next_finger)
      tipTerm(home_key_[f], key_hovers_[home_key_[f]], weights_[w_hover_]);
  // Every other key stays up (accidental presses are typing errors).
  for (int k = 0; k < nkeys_; ++k)
    scratch.key_scales[k] = (k == target.current || k == target.next) ? 0.0 : 1.0 / key_travel_[k];
  jointResidual(m, d, key_joints_, scratch.key_targets.data(), scratch.key_scales.data(), derivatives, buf);
  total += addResidualCost(scale * weights_[w_other_keys_], Norm::quadratic(), buf, out);

  jointResidual(m, d, hand_joints_, rest_targets_.data(), unit_scales_.data(), derivatives, buf);
  total += addResidualCost(scale * weights_[w_posture_], Norm::quadratic(), buf, out);

  if (u) {
    total += out ? control_effort_.addDerivatives(*u, weights_[w_control_], weights_[w_synergy_], *out)
                 : control_effort_.value(*u, weights_[w_control_], weights_[w_synergy_]);
  }
  return total;
}

double TypeTask::runningCost(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double t,
                             TaskScratch& s) const {
  return cost(m, d, &u, t, s, nullptr, 1.0);
}

double TypeTask::terminalCost(const mjModel* m, const mjData* d, double t, TaskScratch& s) const {
  return cost(m, d, nullptr, t, s, nullptr, terminal_scale_);
}

double TypeTask::runningCostDerivatives(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double t,
                                        TaskScratch& s, CostDerivatives& out) const {
  return cost(m, d, &u, t, s, &out, 1.0);
}

double TypeTask::terminalCostDerivatives(const mjModel* m, const mjData* d, double t, TaskScratch& s,
                                         CostDerivatives& out) const {
  return cost(m, d, nullptr, t, s, &out, terminal_scale_);
}

}  // namespace adroit_mpc
