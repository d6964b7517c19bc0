// Reusable cost terms of the behaviour tasks (thesis 6.5) and of the trajectory-centric trainer
// (thesis 8.4.1 positioning, 8.4.2 rotation): a residual r(x) with its Jacobian in the
// planner's tangent space, passed through a norm n(r), weighted, and accumulated with the
// Gauss-Newton approximation  l = w n(r),  lx = w J' n_r,  lxx = w J' n_rr J.
//
// Tangent space (as mjd_transitionFD): dx = [dq (nv) | dv (nv) | act (na)], where a position
// perturbation dq is applied with mj_integratePos (free-joint rotations in the body frame).
// mj_jac* Jacobians are exactly d(world point)/d(dq) in that convention.
//
// Usage: fill a ResidualBuffer with one of the *Residual functions (after mj_forward on the
// knot's state), then addResidualCost(). Nothing here allocates after the buffers are built;
// the buffers are per thread, the term descriptions (BodyPoint, DofList...) are shared.
#pragma once

#include <adroit_mpc/task.h>

#include <mujoco/mujoco.h>

#include <Eigen/Dense>
#include <string>
#include <vector>

namespace adroit_mpc {

// n(r): kQuadratic 0.5 |r|^2; kSmoothAbs sqrt(|r|^2 + p^2) - p (quadratic within p, then
// linear: a far goal does not dominate); kLogCosh p^2 sum log(cosh(r_i / p)) (per component).
enum class NormKind { kQuadratic, kSmoothAbs, kLogCosh };

struct Norm {
  NormKind kind = NormKind::kQuadratic;
  double p = 0.01;  // smoothing scale in the residual's units (not used by kQuadratic)

  static Norm quadratic() { return {NormKind::kQuadratic, 1.0}; }
  static Norm smoothAbs(double p) { return {NormKind::kSmoothAbs, p}; }
  static Norm logCosh(double p) { return {NormKind::kLogCosh, p}; }

  double value(const Eigen::Ref<const Eigen::VectorXd>& r) const;
  // Value, gradient g = dn/dr and Hessian H = d2n/dr2 (positive semi-definite for every kind).
  // g and H must be sized r.size() (and r.size() x r.size()) by the caller.
  double evaluate(const Eigen::Ref<const Eigen::VectorXd>& r, Eigen::Ref<Eigen::VectorXd> g,
                  Eigen::Ref<Eigen::MatrixXd> H) const;
};

// A residual and its Jacobian blocks for one thread. Sized once for the model and the
// largest residual dimension it will hold.
struct ResidualBuffer {
  ResidualBuffer() = default;
  ResidualBuffer(const mjModel* model, int max_dim);  // allocates

  int dim = 0;               // rows in use
  bool uses_q = false;       // jq holds d r / d dq
  bool uses_v = false;       // jv holds d r / d dv
  Eigen::VectorXd r;         // max_dim
  Eigen::MatrixXd jq, jv;    // max_dim x nv
  // scratch
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> jac_a, jac_b, jac_rot;  // 3 x nv
  Eigen::VectorXd g;
  Eigen::MatrixXd H, HJ;     // max_dim x max_dim, max_dim x nv
};

// A point fixed in a body (a site, or an offset from a body's frame), or in the world.
struct BodyPoint {
  int body = -1;                                 // -1: fixed world point
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();  // body frame (world frame when body = -1)

  // Throw std::invalid_argument("... unknown site 'x'") when the name is not in the model.
  static BodyPoint site(const mjModel* model, const std::string& name);
  static BodyPoint bodyFrame(const mjModel* model, const std::string& name,
                             const Eigen::Vector3d& offset = Eigen::Vector3d::Zero());
  static BodyPoint world(const Eigen::Vector3d& position) { return {-1, position}; }

  Eigen::Vector3d position(const mjData* data) const;
};

// Degrees of freedom (velocity coordinates) with a scale each: r_i = scale_i * qvel[dof_i].
struct DofList {
  std::vector<int> dof;
  std::vector<double> scale;
  int size() const { return static_cast<int>(dof.size()); }
  // The six dofs of a free joint: linear (world) scaled 1, angular (body frame) scaled
  // `angular_scale` (a length, so both parts are in m/s). Throws for a non-free joint.
  static DofList freeJoint(const mjModel* model, const std::string& joint, double angular_scale);
};

// Scalar (hinge / slide) joints: r_i = scale_i * (qpos[adr_i] - target_i).
struct JointList {
  std::vector<int> joint, qpos_adr, dof_adr;
  int size() const { return static_cast<int>(joint.size()); }
  // Throws std::invalid_argument naming an unknown or non-scalar joint.
  static JointList named(const mjModel* model, const std::vector<std::string>& names);
  // Every hinge and slide joint whose name passes `keep` (e.g. the robot's joints).
  template <class Predicate>
  static JointList where(const mjModel* model, Predicate keep);
};

// r = a - b (3). Jacobian jq = J_a - J_b.
void pointResidual(const mjModel* m, const mjData* d, const BodyPoint& a, const BodyPoint& b, bool derivatives,
                   ResidualBuffer& buf);
// r = max(0, clearance - |a - b|) (1): zero once the points are `clearance` apart.
void clearanceResidual(const mjModel* m, const mjData* d, const BodyPoint& a, const BodyPoint& b, double clearance,
                       bool derivatives, ResidualBuffer& buf);
// r = |a - c| - radius (1): signed distance of the point a from the sphere of `radius` about
// the point c (negative inside), e.g. a fingertip to a ball's surface. Jacobian
// n' (J_a - J_c), n = (a - c) / |a - c|; flat (zero) where a == c and n is undefined.
void sphereSurfaceResidual(const mjModel* m, const mjData* d, const BodyPoint& a, const BodyPoint& c,
                           double radius, bool derivatives, ResidualBuffer& buf);
// r = max(0, (a - b)_z - height) (1): zero while a is at most `height` above b in world z
// (negative height: at least that far below), e.g. fingertips below a ball's equator.
void aboveResidual(const mjModel* m, const mjData* d, const BodyPoint& a, const BodyPoint& b, double height,
                   bool derivatives, ResidualBuffer& buf);
// r_i = scale_i * qvel[dof_i]. Jacobian: rows of the identity in the velocity block.
void velocityResidual(const mjModel* m, const mjData* d, const DofList& dofs, bool derivatives, ResidualBuffer& buf);
// r = axis_scale .* e, e = mju_subQuat(body orientation, target): the rotation vector from the
// target to the body, in the target frame (|e| = angle, < pi). Jacobian
// diag(axis_scale) Jr^-1(e) R_body' J_rot, with J_rot = mj_jacBody's rotational part and Jr^-1
// the inverse right Jacobian of SO(3). Zero axis_scale entries ignore rotations about that axis
// (e.g. a bottle's spin about its own axis).
void orientationResidual(const mjModel* m, const mjData* d, int body, const Eigen::Quaterniond& target,
                         const Eigen::Vector3d& axis_scale, bool derivatives, ResidualBuffer& buf);
// r_i = scales[i] * (qpos[adr_i] - targets[i]) for the joints of the list (arrays of size()).
void jointResidual(const mjModel* m, const mjData* d, const JointList& joints, const double* targets,
                   const double* scales, bool derivatives, ResidualBuffer& buf);

// Adds weight * norm(r) to the cost and, when out is given, its gradient and Gauss-Newton
// Hessian to out.lx / out.lxx (state blocks only). Returns weight * norm(r). Weight 0 skips.
double addResidualCost(double weight, const Norm& norm, ResidualBuffer& buf, CostDerivatives* out);

// Control effort (thesis 6.5 "regular control penalisation", 6.4.5 synergies):
//   0.5 w_actuator sum ((u_i - lo_i) / (hi_i - lo_i))^2  over the model's actuators (tension
//   above the range's lower end, normalised so every cylinder size costs alike)
// + 0.5 w_synergy  sum s_j^2  over the synergy activations after them (in [-1, 1]).
class ControlEffort {
 public:
  void bind(const mjModel* model, int synergy_dims);  // allocates
  int size() const { return static_cast<int>(lower_.size()) + synergy_dims_; }
  double value(const Eigen::VectorXd& u, double w_actuator, double w_synergy) const;
  // Adds the gradient and (diagonal, exact) Hessian to out.lu / out.luu; returns the cost.
  double addDerivatives(const Eigen::VectorXd& u, double w_actuator, double w_synergy, CostDerivatives& out) const;

 private:
  Eigen::VectorXd lower_, inv_range_;
  int synergy_dims_ = 0;
};

// Inverse right Jacobian of SO(3) at rotation vector e: log(exp(e) exp(w)) ~ e + Jr^-1(e) w.
Eigen::Matrix3d inverseRightJacobianSO3(const Eigen::Vector3d& e);

template <class Predicate>
JointList JointList::where(const mjModel* model, Predicate keep) {
  JointList list;
  for (int j = 0; j < model->njnt; ++j) {
    if (model->jnt_type[j] != mjJNT_HINGE && model->jnt_type[j] != mjJNT_SLIDE) continue;
    const char* name = mj_id2name(model, mjOBJ_JOINT, j);
    if (!name || !keep(std::string(name))) continue;
    list.joint.push_back(j);
    list.qpos_adr.push_back(model->jnt_qposadr[j]);
    list.dof_adr.push_back(model->jnt_dofadr[j]);
  }
  return list;
}

}  // namespace adroit_mpc
