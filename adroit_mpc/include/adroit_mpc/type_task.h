// Typing on the numeric keypad (thesis 6.5). Keys are pre-assigned to fingers (a "heat map"
// from the layout: each key column goes to a different fingertip, the assignment with the
// least summed horizontal fingertip-to-key distance at a keyframe; YAML overrides per key).
// Costs, with the smooth steps S_up / S_dn = 1 - S_up as coefficients (smooth_step.h):
//   S_up x (current key pressed towards full travel + its finger's tip to the key top, from
//     above: approachFromAbove)
//   S_dn x (next key pressed + the next finger's tip to its key top)
//   S_up x next key hover (the next finger above its key, when it is another finger)
//   + home hover: every other finger with keys above its home key (its key nearest to it at
//     the keyframe), at the same weight: no fingertip idles within reach of a key
//   + other keys stay up + light posture towards the rest keyframe + control effort.
// S_up rises at the last key event and falls key_period later (never sooner than min_lead
// after the latest observation), so the plan runs through the transition to the next key.
// A key still held from its last press must first come up (repeated keys).
// Auto-correct: a wrong key makes backspace ("bs") the target, then the intended key again.
//
// observe() (node thread, estimated state) registers a press when a key joint reaches
// -keypad_press_depth (the model's custom numeric) and its release above -release_depth.
// Parameters and defaults: config/tasks/type.yaml (defaultTaskParams("type")).
#pragma once

#include <adroit_mpc/cost_terms.h>
#include <adroit_mpc/smooth_step.h>
#include <adroit_mpc/task.h>
#include <adroit_mpc/task_params.h>

#include <array>
#include <string>
#include <vector>

namespace adroit_mpc {

// The residual r = tip - key top of pointResidual (buf, with its Jacobian), made to approach
// from above: r_z -= height * rho^2 / (rho^2 + radius^2), rho = |r_xy|, so the target is the key
// top when the tip is over it and rises to `height` above it as the tip strays sideways
// (half of it at rho = radius). radius or height 0: unchanged.
void approachFromAbove(double height, double radius, ResidualBuffer& buf);

class TypeTask : public Task {
 public:
  static constexpr int kMaxKeys = 16;
  static constexpr int kMaxSequence = 64;
  static constexpr int kNoKey = -1;
  // Fingertip sites, in finger order: ff mf rf lf th.
  static const std::array<const char*, 5>& fingerNames();  // "ff" ...
  static const std::array<const char*, 5>& fingertipSites();  // "S_fftip" ...

  explicit TypeTask(const TaskParams& params = {});
  static TaskParams defaults();

  std::string name() const override { return "type"; }
  std::unique_ptr<Task> clone() const override { return std::make_unique<TypeTask>(*this); }
  void copyParametersFrom(const Task& other) override;

  void bind(const mjModel* model, int synergy_dims) override;
  std::unique_ptr<TaskScratch> makeScratch(const mjModel* model) const override;

  double runningCost(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double t,
                     TaskScratch& s) const override;
  double terminalCost(const mjModel* m, const mjData* d, double t, TaskScratch& s) const override;
  double runningCostDerivatives(const mjModel* m, const mjData* d, const Eigen::VectorXd& u, double t,
                                TaskScratch& s, CostDerivatives& out) const override;
  double terminalCostDerivatives(const mjModel* m, const mjData* d, double t, TaskScratch& s,
                                 CostDerivatives& out) const override;

  // {"key", label} per registered press, {"error", "pressed 8 instead of 7"} for a wrong key,
  // {"done", sequence} when the sequence is typed.
  std::vector<TaskEvent> observe(const mjModel* m, const mjData* d, double t) override;
  // Digits only, at most kMaxSequence; restarts the typing.
  bool setSequence(const std::string& keys, std::string* why) override;

  std::vector<std::string> weightNames() const override { return weights_.names(); }
  double weight(const std::string& name) const override { return weights_.get(name); }
  void setWeight(const std::string& name, double value) override { weights_.set(name, value); }

  // Keys still to type: pending backspaces + keys of the sequence not typed yet.
  double error(const mjModel* m, const mjData* d) const override;

  // After bind(): the key labels (model order), each key's finger (index into fingerNames()).
  const std::vector<std::string>& keyLabels() const { return labels_; }
  int fingerOfKey(const std::string& label) const;
  // The key to press now / after it (labels; "" when none).
  std::string currentTarget() const;
  std::string nextTarget() const;
  std::string sequence() const { return std::string(sequence_.data(), sequence_length_); }
  int typedCorrectly() const { return matched_; }
  int pendingBackspaces() const { return wrong_; }
  // Since the sequence was given: every registered press, and those of a key other than the
  // one expected next with the auto-correction replayed (after a wrong key, backspace is
  // expected). typedCorrectly() forgives a wrong key once it is backspaced; this count keeps
  // it, so a run that reaches every key by typing and deleting wrong ones shows as such.
  int presses() const { return presses_; }
  int wrongPresses() const { return wrong_presses_; }
  // The S_up step of the current key at the present state of the typing.
  SmoothStep currentStep() const;

 private:
  struct Targets {
    int current = kNoKey, next = kNoKey;
  };
  Targets targets() const;
  int keyOfChar(char c) const;
  double cost(const mjModel* m, const mjData* d, const Eigen::VectorXd* u, double t, TaskScratch& s,
              CostDerivatives* out, double scale) const;
  void checkBound() const;

  WeightTable weights_;
  int w_press_, w_approach_, w_hover_, w_other_keys_, w_posture_, w_control_, w_synergy_;
  double terminal_scale_, hover_height_, approach_smoothing_, key_period_, min_lead_, step_smoothness_;
  double release_depth_, approach_radius_;
  double horizon_hint_, planner_dt_hint_;
  std::string assignment_keyframe_;
  std::vector<std::pair<std::string, int>> assignment_overrides_;  // label -> finger

  // Live typing state (copied by copyParametersFrom without allocation).
  std::array<char, kMaxSequence> sequence_{};
  int sequence_length_ = 0;
  int matched_ = 0;  // keys of the sequence typed correctly, in order
  int wrong_ = 0;    // wrong keys typed after them (each needs a backspace)
  int presses_ = 0, wrong_presses_ = 0;  // since setSequence (presses(), wrongPresses())
  std::array<bool, kMaxKeys> held_{};
  double t_event_ = 0, t_observed_ = 0;

  // Resolved by bind().
  bool bound_ = false;
  int nx_ = 0, nu_total_ = 0, nkeys_ = 0;
  double press_depth_ = 0;
  std::vector<std::string> labels_;
  JointList key_joints_;
  std::vector<double> key_travel_;                // m, per key (-range low)
  std::vector<BodyPoint> key_tops_;               // moving top centre of each key
  std::vector<BodyPoint> key_hovers_;             // fixed world points above each key
  std::vector<int> key_finger_;                   // per key
  std::array<int, 5> home_key_{};                 // per finger: its key nearest at the keyframe (kNoKey: none)
  std::array<BodyPoint, 5> fingertips_{};
  std::array<int, 10> digit_key_{};               // '0'..'9' -> key index (kNoKey if absent)
  int backspace_key_ = kNoKey;
  JointList hand_joints_;
  std::vector<double> rest_targets_, unit_scales_;
  ControlEffort control_effort_;
};

}  // namespace adroit_mpc
