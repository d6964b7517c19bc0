// Synergy augmentation of the control space (thesis 6.4.5): five extra controls on top of
// the individual actuators, four finger curls (FF, MF, RF, LF) and one spread of the four
// fingers. The planner's control vector is u = [actuator tensions (nu) | activations (5)];
// the model receives ctrl = clamp(u_act + S s, ctrlrange) with the linear map S (nu x 5).
//
// A curl pulls the finger's MCP (J2) and PIP/DIP (J1) flexors with their full range per
// unit activation and releases the extensors by the same amount (negative curl: the
// reverse). The spread drives the abduction joints J3 of the four fingers away from the
// hand's middle, each in proportion to its knuckle's distance from it (the middle finger,
// near the centre, moves least); the directions are read from the model's kinematics.
#pragma once

#include <mujoco/mujoco.h>

#include <Eigen/Dense>
#include <array>
#include <string>

namespace adroit_mpc {

class Synergies {
 public:
  static constexpr int kCount = 5;
  static const std::array<std::string, kCount>& names();  // curl_FF ... curl_LF, spread

  Synergies() = default;
  // Resolves the finger actuators by name; throws std::invalid_argument naming the first
  // missing actuator or joint.
  explicit Synergies(const mjModel* model);

  const Eigen::MatrixXd& map() const { return S_; }  // nu x 5

  // ctrl = clamp(u_act + S s, ctrlrange). u has nu + 5 entries; ctrl has nu. No allocation.
  void apply(const double* u, double* ctrl) const;
  // Same, and writes which actuators were not clamped (derivative of the clamp: 1 or 0).
  void apply(const double* u, double* ctrl, double* ctrl_derivative) const;

  // Activations that best explain ctrl (least squares on each antagonistic pair's net tension
  // flex - ext). With zero individual controls, ctrl = clamp(S s) keeps one side of every
  // pair slack and the net tension of the pair is exactly the synergy's, so
  // project(apply([0 | s])) == s for s in [-1, 1]^5. No allocation after construction.
  void project(const double* ctrl, double* s) const;

 private:
  int nu_ = 0;
  Eigen::MatrixXd S_;
  Eigen::VectorXd lower_, upper_;
  Eigen::MatrixXd net_;          // pairs x nu: +1 flexor, -1 extensor
  Eigen::MatrixXd projection_;   // 5 x pairs: pseudo-inverse of the net map of S from zero
  mutable Eigen::VectorXd net_tension_;
};

}  // namespace adroit_mpc
