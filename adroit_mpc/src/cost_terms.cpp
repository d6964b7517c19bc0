#include "adroit_mpc/cost_terms.h"

#include <cmath>
#include <stdexcept>

namespace adroit_mpc {

namespace {

void requireRows(const ResidualBuffer& buf, int dim, const char* what) {
  if (buf.r.size() < dim)
    throw std::invalid_argument(std::string(what) + ": residual of " + std::to_string(dim) +
                                " rows does not fit a buffer of " + std::to_string(buf.r.size()));
}

// World position and 3 x nv translational Jacobian of a point into `jac`.
void pointJacobian(const mjModel* m, const mjData* d, const BodyPoint& p, const Eigen::Vector3d& world,
                   Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>& jac) {
  if (p.body < 0) {
    jac.setZero();
    return;
  }
  mj_jac(m, d, jac.data(), nullptr, world.data(), p.body);
}

}  // namespace

// ---------------------------------------------------------------------------------- Norm

double Norm::value(const Eigen::Ref<const Eigen::VectorXd>& r) const {
  switch (kind) {
    case NormKind::kQuadratic:
      return 0.5 * r.squaredNorm();
    case NormKind::kSmoothAbs:
      return std::sqrt(r.squaredNorm() + p * p) - p;
    case NormKind::kLogCosh: {
      double sum = 0;
      for (int i = 0; i < r.size(); ++i) {
        // log(cosh(z)) = |z| + log1p(exp(-2|z|)) - log 2, safe for large |z|.
        const double z = std::abs(r[i] / p);
        sum += z + std::log1p(std::exp(-2 * z)) - std::log(2.0);
      }
      return p * p * sum;
    }
  }
  return 0;
}

double Norm::evaluate(const Eigen::Ref<const Eigen::VectorXd>& r, Eigen::Ref<Eigen::VectorXd> g,
                      Eigen::Ref<Eigen::MatrixXd> H) const {
  switch (kind) {
    case NormKind::kQuadratic:
      g = r;
      H.setIdentity();
      break;
    case NormKind::kSmoothAbs: {
      const double s = std::sqrt(r.squaredNorm() + p * p);
      g = r / s;
      // Exact Hessian (I - r r' / s^2) / s: eigenvalues 1/s and p^2/s^3, so PSD.
      H.noalias() = -(g * g.transpose()) / s;
      H.diagonal().array() += 1.0 / s;
      break;
    }
    case NormKind::kLogCosh:
      H.setZero();
      for (int i = 0; i < r.size(); ++i) {
        const double th = std::tanh(r[i] / p);
        g[i] = p * th;
        H(i, i) = 1 - th * th;
      }
      break;
  }
  return value(r);
}

// ---------------------------------------------------------------------------------- buffers

ResidualBuffer::ResidualBuffer(const mjModel* model, int max_dim) {
  if (max_dim < 1) throw std::invalid_argument("ResidualBuffer: max_dim must be >= 1");
  const int nv = model->nv;
  r = Eigen::VectorXd::Zero(max_dim);
  jq = Eigen::MatrixXd::Zero(max_dim, nv);
  jv = Eigen::MatrixXd::Zero(max_dim, nv);
  jac_a.setZero(3, nv);
  jac_b.setZero(3, nv);
  jac_rot.setZero(3, nv);
  g = Eigen::VectorXd::Zero(max_dim);
  H = Eigen::MatrixXd::Zero(max_dim, max_dim);
  HJ = Eigen::MatrixXd::Zero(max_dim, nv);
}

BodyPoint BodyPoint::site(const mjModel* model, const std::string& name) {
  const int id = mj_name2id(model, mjOBJ_SITE, name.c_str());
  if (id < 0) throw std::invalid_argument("the model has no site '" + name + "'");
  return {model->site_bodyid[id], Eigen::Vector3d(model->site_pos + 3 * id)};
}

BodyPoint BodyPoint::bodyFrame(const mjModel* model, const std::string& name, const Eigen::Vector3d& offset) {
  const int id = mj_name2id(model, mjOBJ_BODY, name.c_str());
  if (id < 0) throw std::invalid_argument("the model has no body '" + name + "'");
  return {id, offset};
}

Eigen::Vector3d BodyPoint::position(const mjData* data) const {
  if (body < 0) return offset;
  const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> R(data->xmat + 9 * body);
  return Eigen::Vector3d(data->xpos + 3 * body) + R * offset;
}

DofList DofList::freeJoint(const mjModel* model, const std::string& joint, double angular_scale) {
  const int id = mj_name2id(model, mjOBJ_JOINT, joint.c_str());
  if (id < 0) throw std::invalid_argument("the model has no joint '" + joint + "'");
  if (model->jnt_type[id] != mjJNT_FREE) throw std::invalid_argument("joint '" + joint + "' is not a free joint");
  DofList list;
  for (int i = 0; i < 6; ++i) {
    list.dof.push_back(model->jnt_dofadr[id] + i);
    list.scale.push_back(i < 3 ? 1.0 : angular_scale);
  }
  return list;
}

JointList JointList::named(const mjModel* model, const std::vector<std::string>& names) {
  JointList list;
  for (const auto& name : names) {
    const int id = mj_name2id(model, mjOBJ_JOINT, name.c_str());
    if (id < 0) throw std::invalid_argument("the model has no joint '" + name + "'");
    if (model->jnt_type[id] != mjJNT_HINGE && model->jnt_type[id] != mjJNT_SLIDE)
      throw std::invalid_argument("joint '" + name + "' is not a hinge or slide joint");
    list.joint.push_back(id);
    list.qpos_adr.push_back(model->jnt_qposadr[id]);
    list.dof_adr.push_back(model->jnt_dofadr[id]);
  }
  return list;
}

// ---------------------------------------------------------------------------------- residuals

void pointResidual(const mjModel* m, const mjData* d, const BodyPoint& a, const BodyPoint& b, bool derivatives,
                   ResidualBuffer& buf) {
  requireRows(buf, 3, "pointResidual");
  const Eigen::Vector3d pa = a.position(d), pb = b.position(d);
  buf.dim = 3;
  buf.uses_q = derivatives;
  buf.uses_v = false;
  buf.r.head<3>() = pa - pb;
  if (!derivatives) return;
  pointJacobian(m, d, a, pa, buf.jac_a);
  pointJacobian(m, d, b, pb, buf.jac_b);
  buf.jq.topRows<3>() = buf.jac_a - buf.jac_b;
}

namespace {

// r = sign * (|a - b| - offset) (1); Jacobian sign * (a - b)' / |a - b| (J_a - J_b), flat where
// `active` is false or the direction is undefined (a = b).
void distanceResidual(const mjModel* m, const mjData* d, const BodyPoint& a, const BodyPoint& b, double offset,
                      double sign, bool clamp_at_zero, bool derivatives, ResidualBuffer& buf) {
  const Eigen::Vector3d pa = a.position(d), pb = b.position(d);
  const Eigen::Vector3d diff = pa - pb;
  const double distance = diff.norm();
  const double r = sign * (distance - offset);
  const bool active = !clamp_at_zero || r > 0;
  buf.dim = 1;
  buf.uses_q = derivatives;
  buf.uses_v = false;
  buf.r[0] = active ? r : 0.0;
  if (!derivatives) return;
  if (!active || distance == 0.0) {
    buf.jq.row(0).setZero();
    return;
  }
  pointJacobian(m, d, a, pa, buf.jac_a);
  pointJacobian(m, d, b, pb, buf.jac_b);
  buf.jq.row(0).noalias() = (sign / distance) * diff.transpose() * (buf.jac_a - buf.jac_b);
}

}  // namespace

void clearanceResidual(const mjModel* m, const mjData* d, const BodyPoint& a, const BodyPoint& b, double clearance,
                       bool derivatives, ResidualBuffer& buf) {
  requireRows(buf, 1, "clearanceResidual");
  distanceResidual(m, d, a, b, clearance, -1.0, true, derivatives, buf);  // max(0, clearance - |a - b|)
}

void sphereSurfaceResidual(const mjModel* m, const mjData* d, const BodyPoint& a, const BodyPoint& c,
                           double radius, bool derivatives, ResidualBuffer& buf) {
  requireRows(buf, 1, "sphereSurfaceResidual");
  distanceResidual(m, d, a, c, radius, 1.0, false, derivatives, buf);  // |a - c| - radius
}

void aboveResidual(const mjModel* m, const mjData* d, const BodyPoint& a, const BodyPoint& b, double height,
                   bool derivatives, ResidualBuffer& buf) {
  requireRows(buf, 1, "aboveResidual");
  const Eigen::Vector3d pa = a.position(d), pb = b.position(d);
  const double excess = pa.z() - pb.z() - height;
  buf.dim = 1;
  buf.uses_q = derivatives;
  buf.uses_v = false;
  buf.r[0] = excess > 0 ? excess : 0.0;
  if (!derivatives) return;
  if (buf.r[0] == 0.0) {  // inactive: flat
    buf.jq.row(0).setZero();
    return;
  }
  pointJacobian(m, d, a, pa, buf.jac_a);
  pointJacobian(m, d, b, pb, buf.jac_b);
  buf.jq.row(0) = buf.jac_a.row(2) - buf.jac_b.row(2);
}

void velocityResidual(const mjModel* m, const mjData* d, const DofList& dofs, bool derivatives, ResidualBuffer& buf) {
  const int n = dofs.size();
  requireRows(buf, n, "velocityResidual");
  buf.dim = n;
  buf.uses_q = false;
  buf.uses_v = derivatives;
  for (int i = 0; i < n; ++i) buf.r[i] = dofs.scale[i] * d->qvel[dofs.dof[i]];
  if (!derivatives) return;
  buf.jv.topRows(n).setZero();
  for (int i = 0; i < n; ++i) buf.jv(i, dofs.dof[i]) = dofs.scale[i];
  (void)m;
}

Eigen::Matrix3d inverseRightJacobianSO3(const Eigen::Vector3d& e) {
  Eigen::Matrix3d E;
  E << 0, -e.z(), e.y(), e.z(), 0, -e.x(), -e.y(), e.x(), 0;
  const double theta = e.norm();
  // Coefficient of E^2: 1/theta^2 - (1 + cos theta) / (2 theta sin theta); series below 1e-4.
  const double c = theta < 1e-4 ? 1.0 / 12.0 + theta * theta / 720.0
                                 : 1.0 / (theta * theta) - (1 + std::cos(theta)) / (2 * theta * std::sin(theta));
  return Eigen::Matrix3d::Identity() + 0.5 * E + c * E * E;
}

void orientationResidual(const mjModel* m, const mjData* d, int body, const Eigen::Quaterniond& target,
                         const Eigen::Vector3d& axis_scale, bool derivatives, ResidualBuffer& buf) {
  requireRows(buf, 3, "orientationResidual");
  const double target_wxyz[4] = {target.w(), target.x(), target.y(), target.z()};
  Eigen::Vector3d e;
  mju_subQuat(e.data(), d->xquat + 4 * body, target_wxyz);
  buf.dim = 3;
  buf.uses_q = derivatives;
  buf.uses_v = false;
  buf.r.head<3>() = axis_scale.cwiseProduct(e);
  if (!derivatives) return;
  mj_jacBody(m, d, nullptr, buf.jac_rot.data(), body);
  const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> R(d->xmat + 9 * body);
  // World angular perturbation w -> body frame R' w -> rotation vector change Jr^-1(e) R' w.
  const Eigen::Matrix3d map = axis_scale.asDiagonal() * inverseRightJacobianSO3(e) * R.transpose();
  buf.jq.topRows<3>().noalias() = map * buf.jac_rot;
}

void jointResidual(const mjModel* m, const mjData* d, const JointList& joints, const double* targets,
                   const double* scales, bool derivatives, ResidualBuffer& buf) {
  const int n = joints.size();
  requireRows(buf, n, "jointResidual");
  buf.dim = n;
  buf.uses_q = derivatives;
  buf.uses_v = false;
  for (int i = 0; i < n; ++i) buf.r[i] = scales[i] * (d->qpos[joints.qpos_adr[i]] - targets[i]);
  if (!derivatives) return;
  buf.jq.topRows(n).setZero();
  for (int i = 0; i < n; ++i) buf.jq(i, joints.dof_adr[i]) = scales[i];
  (void)m;
}

// ---------------------------------------------------------------------------------- accumulation

double addResidualCost(double weight, const Norm& norm, ResidualBuffer& buf, CostDerivatives* out) {
  if (weight == 0.0 || buf.dim == 0) return 0.0;
  const int n = buf.dim;
  const auto r = buf.r.head(n);
  if (!out) return weight * norm.value(r);
  const double value = norm.evaluate(r, buf.g.head(n), buf.H.topLeftCorner(n, n));
  const int nv = static_cast<int>(buf.jq.cols());
  const auto g = buf.g.head(n);
  const auto H = buf.H.topLeftCorner(n, n);
  auto HJ = buf.HJ.topRows(n);
  // Blocks of dx = [dq | dv | act]: q at 0, v at nv.
  if (buf.uses_q) {
    const auto J = buf.jq.topRows(n);
    out->lx.segment(0, nv).noalias() += weight * J.transpose() * g;
    HJ.noalias() = weight * H * J;
    out->lxx.block(0, 0, nv, nv).noalias() += J.transpose() * HJ;
  }
  if (buf.uses_v) {
    const auto J = buf.jv.topRows(n);
    out->lx.segment(nv, nv).noalias() += weight * J.transpose() * g;
    HJ.noalias() = weight * H * J;
    out->lxx.block(nv, nv, nv, nv).noalias() += J.transpose() * HJ;
    if (buf.uses_q) {  // cross blocks; HJ holds w H Jv
      const auto Jq = buf.jq.topRows(n);
      out->lxx.block(0, nv, nv, nv).noalias() += Jq.transpose() * HJ;
      out->lxx.block(nv, 0, nv, nv).noalias() += HJ.transpose() * Jq;
    }
  }
  return weight * value;
}

// ---------------------------------------------------------------------------------- control

void ControlEffort::bind(const mjModel* model, int synergy_dims) {
  if (synergy_dims < 0) throw std::invalid_argument("ControlEffort: synergy_dims must be >= 0");
  lower_.resize(model->nu);
  inv_range_.resize(model->nu);
  for (int i = 0; i < model->nu; ++i) {
    const double lo = model->actuator_ctrlrange[2 * i], hi = model->actuator_ctrlrange[2 * i + 1];
    const bool limited = model->actuator_ctrllimited[i] && hi > lo;
    lower_[i] = limited ? lo : 0.0;
    inv_range_[i] = limited ? 1.0 / (hi - lo) : 1.0;
  }
  synergy_dims_ = synergy_dims;
}

double ControlEffort::value(const Eigen::VectorXd& u, double w_actuator, double w_synergy) const {
  const int nu = static_cast<int>(lower_.size());
  if (u.size() != size())
    throw std::invalid_argument("ControlEffort: control has " + std::to_string(u.size()) + " entries, expected " +
                                std::to_string(size()));
  const double actuators = ((u.head(nu) - lower_).cwiseProduct(inv_range_)).squaredNorm();
  const double synergies = u.tail(synergy_dims_).squaredNorm();
  return 0.5 * (w_actuator * actuators + w_synergy * synergies);
}

double ControlEffort::addDerivatives(const Eigen::VectorXd& u, double w_actuator, double w_synergy,
                                     CostDerivatives& out) const {
  const double cost = value(u, w_actuator, w_synergy);
  const int nu = static_cast<int>(lower_.size());
  for (int i = 0; i < nu; ++i) {
    const double s2 = inv_range_[i] * inv_range_[i];
    out.lu[i] += w_actuator * (u[i] - lower_[i]) * s2;
    out.luu(i, i) += w_actuator * s2;
  }
  for (int j = 0; j < synergy_dims_; ++j) {
    out.lu[nu + j] += w_synergy * u[nu + j];
    out.luu(nu + j, nu + j) += w_synergy;
  }
  return cost;
}

}  // namespace adroit_mpc
