#include "adroit_mpc/synergies.h"

#include <adroit_core/model_tables.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace adroit_mpc {
namespace {

const char* const kFingers[4] = {"FF", "MF", "RF", "LF"};

int requireActuator(const adroit::ModelTables& tables, const std::string& name) {
  auto index = tables.actuators.find(name);
  if (!index) throw std::invalid_argument("synergies: the model has no actuator '" + name + "'");
  return *index;
}

}  // namespace

const std::array<std::string, Synergies::kCount>& Synergies::names() {
  static const std::array<std::string, kCount> n = {"curl_FF", "curl_MF", "curl_RF", "curl_LF", "spread"};
  return n;
}

Synergies::Synergies(const mjModel* m) : nu_(m->nu) {
  adroit::ModelTables tables(m);
  S_.setZero(nu_, kCount);
  lower_.resize(nu_);
  upper_.resize(nu_);
  for (int i = 0; i < nu_; ++i) {
    const bool limited = m->actuator_ctrllimited[i];
    lower_[i] = limited ? m->actuator_ctrlrange[2 * i] : -mjMAXVAL;
    upper_[i] = limited ? m->actuator_ctrlrange[2 * i + 1] : mjMAXVAL;
  }
  auto range = [&](int a) {
    if (!m->actuator_ctrllimited[a])
      throw std::invalid_argument("synergies: actuator '" + tables.actuators.name(a) + "' has no ctrlrange");
    return m->actuator_ctrlrange[2 * a + 1] - m->actuator_ctrlrange[2 * a];
  };
  std::vector<std::pair<int, int>> pairs;  // (flexor, extensor) of every joint a synergy drives
  auto drive = [&](int column, const std::string& joint, double weight) {
    const int flex = requireActuator(tables, "A_" + joint + "_flex");
    const int ext = requireActuator(tables, "A_" + joint + "_ext");
    S_(flex, column) = weight * range(flex);
    S_(ext, column) = -weight * range(ext);
    pairs.emplace_back(flex, ext);
  };
  for (int f = 0; f < 4; ++f) {
    drive(f, std::string(kFingers[f]) + "J2", 1.0);  // MCP flexion
    drive(f, std::string(kFingers[f]) + "J1", 1.0);  // PIP/DIP tendon
  }

  // Spread: which sign of each J3 moves the fingertip away from the middle of the hand, from
  // the kinematics at qpos0 (positions of the knuckles along the line LF -> FF knuckle).
  mjData* d = mj_makeData(m);
  mj_kinematics(m, d);
  double anchor[4][3], motion[4][3];
  for (int f = 0; f < 4; ++f) {
    const std::string jname = std::string(kFingers[f]) + "J3";
    auto j = tables.joints.find(jname);
    std::string prefix = kFingers[f];
    for (char& c : prefix) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    auto tip = tables.sites.find("S_" + prefix + "tip");
    if (!j || !tip) {
      mj_deleteData(d);
      throw std::invalid_argument("synergies: the model has no abduction joint '" + jname +
                                  "' or its fingertip site");
    }
    mju_copy3(anchor[f], d->xanchor + 3 * *j);
    double lever[3];
    mju_sub3(lever, d->site_xpos + 3 * *tip, anchor[f]);
    mju_cross(motion[f], d->xaxis + 3 * *j, lever);  // fingertip velocity for +1 rad/s
  }
  mj_deleteData(d);
  double lateral[3];
  mju_sub3(lateral, anchor[0], anchor[3]);
  mju_normalize3(lateral);
  double offset[4], centre = 0, reach = 0;
  for (int f = 0; f < 4; ++f) centre += (offset[f] = mju_dot3(anchor[f], lateral)) / 4;
  for (int f = 0; f < 4; ++f) reach = std::max(reach, std::fabs(offset[f] - centre));
  for (int f = 0; f < 4; ++f) {
    const double outward = offset[f] - centre;  // + on the FF side
    const double direction = mju_dot3(motion[f], lateral) >= 0 ? 1.0 : -1.0;
    drive(4, std::string(kFingers[f]) + "J3", direction * outward / reach);
  }

  // Net tension of every driven pair; with zero individual controls clamp(S s) leaves
  // one side of each pair at zero and the other at |S s|, so net = (net_ S / 2) s.
  net_.setZero(pairs.size(), nu_);
  for (std::size_t p = 0; p < pairs.size(); ++p) {
    net_(p, pairs[p].first) = 1;
    net_(p, pairs[p].second) = -1;
  }
  const Eigen::MatrixXd net_map = 0.5 * net_ * S_;
  // Full column rank (each synergy drives its own pairs): the pseudo-inverse is (N'N)^-1 N'.
  const Eigen::MatrixXd normal = net_map.transpose() * net_map;
  projection_ = normal.ldlt().solve(net_map.transpose());
  net_tension_.resize(pairs.size());
}

void Synergies::apply(const double* u, double* ctrl) const {
  Eigen::Map<Eigen::VectorXd> out(ctrl, nu_);
  out = Eigen::Map<const Eigen::VectorXd>(u, nu_);
  out.noalias() += S_ * Eigen::Map<const Eigen::Matrix<double, kCount, 1>>(u + nu_);
  out = out.cwiseMax(lower_).cwiseMin(upper_);
}

void Synergies::apply(const double* u, double* ctrl, double* ctrl_derivative) const {
  Eigen::Map<Eigen::VectorXd> out(ctrl, nu_);
  out = Eigen::Map<const Eigen::VectorXd>(u, nu_);
  out.noalias() += S_ * Eigen::Map<const Eigen::Matrix<double, kCount, 1>>(u + nu_);
  for (int i = 0; i < nu_; ++i) {
    // At a bound exactly (the minimum-tension warm start) the one-sided derivative inward
    // is 1: keeping it lets the optimiser pull away from the bound.
    const bool clamped = out[i] < lower_[i] || out[i] > upper_[i];
    ctrl_derivative[i] = clamped ? 0.0 : 1.0;
    out[i] = std::min(std::max(out[i], lower_[i]), upper_[i]);
  }
}

void Synergies::project(const double* ctrl, double* s) const {
  net_tension_.noalias() = net_ * Eigen::Map<const Eigen::VectorXd>(ctrl, nu_);
  Eigen::Map<Eigen::Matrix<double, kCount, 1>>(s).noalias() = projection_ * net_tension_;
}

}  // namespace adroit_mpc
