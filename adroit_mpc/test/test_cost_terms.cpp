// Cost terms against finite differences on a small real MuJoCo model: every analytic gradient
// (tangent space: dq via mj_integratePos, dv, u) equals the central-difference gradient of the
// cost; Gauss-Newton Hessians are symmetric PSD, and exact where the residual is linear.
#include <gtest/gtest.h>

#include <adroit_core/mujoco_model.h>

#include <Eigen/Cholesky>
#include <cmath>
#include <functional>

#include "adroit_mpc/cost_terms.h"

namespace {

using adroit_mpc::BodyPoint;
using adroit_mpc::CostDerivatives;
using adroit_mpc::Norm;
using adroit_mpc::ResidualBuffer;

// H + tolerance I has a Cholesky factor <=> every eigenvalue of H is above -tolerance.
bool positiveSemiDefinite(const Eigen::MatrixXd& H, double tolerance) {
  Eigen::MatrixXd shifted = H;
  shifted.diagonal().array() += tolerance;
  return shifted.llt().info() == Eigen::Success;
}

// Two-link arm (hinges), a free box, a slider: positions, rotations and scalar joints.
const char* kModel = R"(
<mujoco>
  <worldbody>
    <body name="upper" pos="0 0 0.5">
      <joint name="shoulder" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02"/>
      <body name="lower" pos="0.3 0 0" quat="0.9 0.1 0.3 0.2">
        <joint name="elbow" type="hinge" axis="0 0 1"/>
        <geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02"/>
        <site name="tip" pos="0.2 0.01 0.02"/>
      </body>
    </body>
    <body name="object" pos="0.4 0.1 0.3">
      <freejoint name="object_root"/>
      <geom type="box" size="0.03 0.02 0.01"/>
    </body>
    <body name="slider" pos="0 0.5 0">
      <joint name="slide" type="slide" axis="1 0 0"/>
      <geom type="sphere" size="0.02"/>
    </body>
  </worldbody>
  <actuator>
    <motor name="m_shoulder" joint="shoulder" ctrlrange="0 10" ctrllimited="true"/>
    <motor name="m_elbow" joint="elbow" ctrlrange="-2 2" ctrllimited="true"/>
  </actuator>
</mujoco>)";

class CostTerms : public ::testing::Test {
 protected:
  void SetUp() override {
    model_ = adroit::loadModelString(kModel).model;
    data_ = adroit::makeData(model_.get());
    m = model_.get();
    d = data_.get();
    nv = m->nv;
    nx = 2 * nv + m->na;
    // A generic state: bent arm, tilted and moving object, displaced slider.
    const double q[] = {0.4, -0.7, 0.45, 0.05, 0.35, 0.8, 0.3, -0.4, 0.33, 0.02};
    mju_copy(d->qpos, q, m->nq);
    mju_normalize4(d->qpos + 5);
    for (int i = 0; i < nv; ++i) d->qvel[i] = 0.3 * std::sin(1.7 * i + 0.4);
    mj_forward(m, d);
    qpos0 = Eigen::Map<Eigen::VectorXd>(d->qpos, m->nq);
    qvel0 = Eigen::Map<Eigen::VectorXd>(d->qvel, nv);
    buf = ResidualBuffer(m, 6);
    out.resize(nx, m->nu);
  }

  // Cost at the state displaced by dx = [dq | dv] from the reference state.
  double costAt(const Eigen::VectorXd& dx, const std::function<double()>& cost) {
    mju_copy(d->qpos, qpos0.data(), m->nq);
    mj_integratePos(m, d->qpos, dx.data(), 1.0);
    for (int i = 0; i < nv; ++i) d->qvel[i] = qvel0[i] + dx[nv + i];
    mj_forward(m, d);
    return cost();
  }

  Eigen::VectorXd fdGradient(const std::function<double()>& cost, double eps = 1e-6) {
    Eigen::VectorXd g(nx), dx = Eigen::VectorXd::Zero(nx);
    for (int i = 0; i < nx; ++i) {
      dx[i] = eps;
      const double plus = costAt(dx, cost);
      dx[i] = -eps;
      const double minus = costAt(dx, cost);
      dx[i] = 0;
      g[i] = (plus - minus) / (2 * eps);
    }
    costAt(dx, cost);  // back to the reference state
    return g;
  }

  // Analytic derivatives of `fill` (a residual function) with `norm` and `weight` at the
  // reference state, checked against FD; returns lxx for further checks.
  Eigen::MatrixXd checkTerm(const std::function<void(bool)>& fill, const Norm& norm, double weight,
                            const char* what) {
    costAt(Eigen::VectorXd::Zero(nx), [] { return 0.0; });
    out.setZero();
    fill(true);
    const double value = adroit_mpc::addResidualCost(weight, norm, buf, &out);
    auto cost = [&] {
      fill(false);
      return adroit_mpc::addResidualCost(weight, norm, buf, nullptr);
    };
    EXPECT_NEAR(value, costAt(Eigen::VectorXd::Zero(nx), cost), 1e-12) << what;
    EXPECT_GT(value, 1e-6) << what << ": the test state must not be at the minimum";
    const Eigen::VectorXd fd = fdGradient(cost);
    for (int i = 0; i < nx; ++i) EXPECT_NEAR(out.lx[i], fd[i], 1e-6 * std::max(1.0, std::abs(fd[i]))) << what << " dx " << i;
    EXPECT_LT((out.lxx - out.lxx.transpose()).cwiseAbs().maxCoeff(), 1e-12) << what;
    EXPECT_TRUE(positiveSemiDefinite(out.lxx, 1e-9 * std::max(1.0, out.lxx.norm()))) << what;
    return out.lxx;
  }

  // FD Hessian from FD of the analytic gradient (for residuals linear in the state).
  Eigen::MatrixXd fdHessian(const std::function<void(bool)>& fill, const Norm& norm, double weight) {
    Eigen::MatrixXd H(nx, nx);
    Eigen::VectorXd dx = Eigen::VectorXd::Zero(nx);
    const double eps = 1e-6;
    auto gradientAt = [&](const Eigen::VectorXd& at) {
      costAt(at, [] { return 0.0; });
      out.setZero();
      fill(true);
      adroit_mpc::addResidualCost(weight, norm, buf, &out);
      return Eigen::VectorXd(out.lx);
    };
    for (int i = 0; i < nx; ++i) {
      dx[i] = eps;
      const Eigen::VectorXd plus = gradientAt(dx);
      dx[i] = -eps;
      const Eigen::VectorXd minus = gradientAt(dx);
      dx[i] = 0;
      H.col(i) = (plus - minus) / (2 * eps);
    }
    costAt(dx, [] { return 0.0; });
    return H;
  }

  adroit::ModelPtr model_;
  adroit::DataPtr data_;
  const mjModel* m = nullptr;
  mjData* d = nullptr;
  int nv = 0, nx = 0;
  Eigen::VectorXd qpos0, qvel0;
  ResidualBuffer buf;
  CostDerivatives out;
};

TEST(Norms, GradientAndHessianMatchFiniteDifferences) {
  const Eigen::Vector3d r(0.03, -0.01, 0.02);
  for (const Norm& norm : {Norm::quadratic(), Norm::smoothAbs(0.02), Norm::logCosh(0.015)}) {
    Eigen::VectorXd g(3);
    Eigen::MatrixXd H(3, 3);
    norm.evaluate(r, g, H);
    const double eps = 1e-7;
    for (int i = 0; i < 3; ++i) {
      Eigen::Vector3d p = r, q = r;
      p[i] += eps;
      q[i] -= eps;
      EXPECT_NEAR(g[i], (norm.value(p) - norm.value(q)) / (2 * eps), 1e-7);
      Eigen::VectorXd gp(3), gq(3);
      Eigen::MatrixXd scratch(3, 3);
      norm.evaluate(p, gp, scratch);
      norm.evaluate(q, gq, scratch);
      for (int j = 0; j < 3; ++j) EXPECT_NEAR(H(j, i), (gp[j] - gq[j]) / (2 * eps), 1e-5);
    }
    EXPECT_EQ(H.llt().info(), Eigen::Success);  // positive definite
  }
}

TEST(Norms, ValuesByHand) {
  const Eigen::Vector2d r(0.3, 0.4);  // |r| = 0.5
  EXPECT_NEAR(Norm::quadratic().value(r), 0.125, 1e-15);
  EXPECT_NEAR(Norm::smoothAbs(1.2).value(r), 1.3 - 1.2, 1e-15);  // sqrt(0.25 + 1.44) = 1.3
  // p^2 (log cosh(0.3) + log cosh(0.4)) with p = 1: ln 1.0453385 + ln 1.0810724
  EXPECT_NEAR(Norm::logCosh(1.0).value(r), 0.0443410 + 0.0779537, 1e-6);
  EXPECT_NEAR(Norm::logCosh(0.001).value(Eigen::Vector2d(50.0, 0.0)), 1e-6 * (50000 - std::log(2.0)), 1e-9);
}

TEST_F(CostTerms, SitePositionToWorldTarget) {
  const BodyPoint tip = BodyPoint::site(m, "tip");
  // The body-point form reproduces MuJoCo's own site position.
  EXPECT_LT((tip.position(d) - Eigen::Vector3d(d->site_xpos)).norm(), 1e-12);
  const BodyPoint target = BodyPoint::world({0.2, 0.1, 0.4});
  checkTerm([&](bool der) { adroit_mpc::pointResidual(m, d, tip, target, der, buf); }, Norm::smoothAbs(0.05), 2.0,
            "site to world (smooth-abs)");
  checkTerm([&](bool der) { adroit_mpc::pointResidual(m, d, tip, target, der, buf); }, Norm::logCosh(0.05), 2.0,
            "site to world (log-cosh)");
}

TEST_F(CostTerms, ObjectToSiteThroughFreeJoint) {
  // The object point is off the body origin, so the free joint's rotation dofs matter too.
  const BodyPoint corner = BodyPoint::bodyFrame(m, "object", {0.03, 0.02, -0.01});
  const BodyPoint tip = BodyPoint::site(m, "tip");
  checkTerm([&](bool der) { adroit_mpc::pointResidual(m, d, corner, tip, der, buf); }, Norm::quadratic(), 3.0,
            "object corner to site");
}

TEST_F(CostTerms, Clearance) {
  const BodyPoint tip = BodyPoint::site(m, "tip");
  const BodyPoint object = BodyPoint::bodyFrame(m, "object");
  const double distance = (tip.position(d) - object.position(d)).norm();
  checkTerm([&](bool der) { adroit_mpc::clearanceResidual(m, d, tip, object, distance + 0.1, der, buf); },
            Norm::quadratic(), 5.0, "clearance (active)");
  adroit_mpc::clearanceResidual(m, d, tip, object, distance - 0.01, true, buf);
  EXPECT_EQ(buf.r[0], 0.0);
  EXPECT_EQ(buf.jq.row(0).cwiseAbs().maxCoeff(), 0.0);
}

TEST_F(CostTerms, PointToSphereSurface) {
  // The arm's tip to the surface of a sphere about a point off the free object's origin, so
  // the tip's hinges and the object's translation and rotation all move the residual.
  const BodyPoint tip = BodyPoint::site(m, "tip");
  const BodyPoint centre = BodyPoint::bodyFrame(m, "object", {0.01, -0.02, 0.015});
  const double distance = (tip.position(d) - centre.position(d)).norm();
  ASSERT_GT(distance, 0.05);
  // Outside, inside, on the surface: the signed distance to the surface.
  for (const double radius : {0.5 * distance, 1.5 * distance, distance}) {
    adroit_mpc::sphereSurfaceResidual(m, d, tip, centre, radius, false, buf);
    ASSERT_EQ(buf.dim, 1);
    EXPECT_NEAR(buf.r[0], distance - radius, 1e-12) << radius;
  }
  checkTerm([&](bool der) { adroit_mpc::sphereSurfaceResidual(m, d, tip, centre, 0.5 * distance, der, buf); },
            Norm::quadratic(), 4.0, "tip outside the sphere");
  checkTerm([&](bool der) { adroit_mpc::sphereSurfaceResidual(m, d, tip, centre, 1.5 * distance, der, buf); },
            Norm::smoothAbs(0.01), 4.0, "tip inside the sphere");
  // A fixed world point: only the object's translation moves the residual, by -n (n the unit
  // direction from the centre to the point).
  const BodyPoint world_point = BodyPoint::world(tip.position(d) + Eigen::Vector3d(0.1, 0.0, 0.0));
  adroit_mpc::sphereSurfaceResidual(m, d, world_point, centre, 0.05, true, buf);
  const int object_dof = m->jnt_dofadr[mj_name2id(m, mjOBJ_JOINT, "object_root")];
  const Eigen::Vector3d n = (world_point.position(d) - centre.position(d)).normalized();
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(buf.jq(0, object_dof + k), -n[k], 1e-12) << k;
  EXPECT_EQ(buf.jq(0, 0), 0.0);  // the arm's hinges do not move a world point or the object
  // Tip at the centre: the direction is undefined, the residual is -radius and flat.
  adroit_mpc::sphereSurfaceResidual(m, d, centre, centre, 0.03, true, buf);
  EXPECT_NEAR(buf.r[0], -0.03, 1e-15);
  EXPECT_EQ(buf.jq.row(0).cwiseAbs().maxCoeff(), 0.0);
}

TEST_F(CostTerms, AboveAHeight) {
  const BodyPoint tip = BodyPoint::site(m, "tip");
  const BodyPoint object = BodyPoint::bodyFrame(m, "object", {0.01, 0.0, -0.02});
  const double dz = tip.position(d).z() - object.position(d).z();
  // Active: the tip is 3 cm higher above the object point than allowed.
  adroit_mpc::aboveResidual(m, d, tip, object, dz - 0.03, false, buf);
  EXPECT_NEAR(buf.r[0], 0.03, 1e-12);
  checkTerm([&](bool der) { adroit_mpc::aboveResidual(m, d, tip, object, dz - 0.03, der, buf); }, Norm::quadratic(),
            5.0, "above (active)");
  // Inactive: lower than allowed, zero and flat.
  adroit_mpc::aboveResidual(m, d, tip, object, dz + 0.01, true, buf);
  EXPECT_EQ(buf.r[0], 0.0);
  EXPECT_EQ(buf.jq.row(0).cwiseAbs().maxCoeff(), 0.0);
}

TEST_F(CostTerms, ObjectVelocity) {
  const auto dofs = adroit_mpc::DofList::freeJoint(m, "object_root", 0.05);
  auto fill = [&](bool der) { adroit_mpc::velocityResidual(m, d, dofs, der, buf); };
  const Eigen::MatrixXd H = checkTerm(fill, Norm::quadratic(), 1.5, "object velocity");
  // Linear residual + quadratic norm: Gauss-Newton is the exact Hessian.
  EXPECT_LT((H - fdHessian(fill, Norm::quadratic(), 1.5)).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_THROW(adroit_mpc::DofList::freeJoint(m, "elbow", 1.0), std::invalid_argument);
}

TEST_F(CostTerms, OrientationOfAFreeBodyFarFromTheTarget) {
  const int body = mj_name2id(m, mjOBJ_BODY, "object");
  // 2 rad away, so the inverse right Jacobian differs clearly from the identity.
  const Eigen::Quaterniond current(d->xquat[4 * body], d->xquat[4 * body + 1], d->xquat[4 * body + 2],
                                   d->xquat[4 * body + 3]);
  const Eigen::Quaterniond target =
      current * Eigen::Quaterniond(Eigen::AngleAxisd(2.0, Eigen::Vector3d(0.3, 1, -0.2).normalized()));
  adroit_mpc::orientationResidual(m, d, body, target, Eigen::Vector3d::Ones(), false, buf);
  EXPECT_NEAR(buf.r.head<3>().norm(), 2.0, 1e-9);
  checkTerm([&](bool der) {
    adroit_mpc::orientationResidual(m, d, body, target, Eigen::Vector3d::Ones(), der, buf);
  }, Norm::quadratic(), 1.0, "free body orientation");
  checkTerm([&](bool der) {
    adroit_mpc::orientationResidual(m, d, body, target, Eigen::Vector3d(0, 1, 0.5), der, buf);
  }, Norm::smoothAbs(0.1), 1.0, "free body orientation, scaled axes");
}

TEST_F(CostTerms, OrientationOfABodyOnHinges) {
  const int body = mj_name2id(m, mjOBJ_BODY, "lower");
  const Eigen::Quaterniond target(0.8, 0.2, -0.5, 0.1);
  checkTerm([&](bool der) {
    adroit_mpc::orientationResidual(m, d, body, target.normalized(), Eigen::Vector3d::Ones(), der, buf);
  }, Norm::quadratic(), 1.0, "hinge chain orientation");
}

TEST_F(CostTerms, OrientationErrorIsTheRotationAngle) {
  const int body = mj_name2id(m, mjOBJ_BODY, "object");
  const Eigen::Quaterniond current(d->xquat[0 + 4 * body], d->xquat[1 + 4 * body], d->xquat[2 + 4 * body],
                                   d->xquat[3 + 4 * body]);
  const Eigen::Quaterniond target = current * Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()));
  adroit_mpc::orientationResidual(m, d, body, target, Eigen::Vector3d::Ones(), false, buf);
  // The body is the target turned by -0.7 rad about the target's z axis.
  EXPECT_LT((buf.r.head<3>() - Eigen::Vector3d(0, 0, -0.7)).norm(), 1e-9);
}

TEST_F(CostTerms, JointPosture) {
  const auto joints = adroit_mpc::JointList::named(m, {"shoulder", "elbow", "slide"});
  const double targets[] = {0.1, 0.2, 0.0}, scales[] = {1.0, 0.5, 10.0};
  auto fill = [&](bool der) { adroit_mpc::jointResidual(m, d, joints, targets, scales, der, buf); };
  const Eigen::MatrixXd H = checkTerm(fill, Norm::quadratic(), 2.0, "joint posture");
  EXPECT_LT((H - fdHessian(fill, Norm::quadratic(), 2.0)).cwiseAbs().maxCoeff(), 1e-5);
  checkTerm(fill, Norm::logCosh(0.1), 2.0, "joint posture (log-cosh)");
  // By hand: 0.5 * 2 * ((0.4-0.1)^2 + (0.5 (-0.7-0.2))^2 + (10 * 0.02)^2) = 0.09 + 0.2025 + 0.04
  adroit_mpc::jointResidual(m, d, joints, targets, scales, false, buf);
  EXPECT_NEAR(adroit_mpc::addResidualCost(2.0, Norm::quadratic(), buf, nullptr), 0.3325, 1e-12);
  EXPECT_THROW(adroit_mpc::JointList::named(m, {"object_root"}), std::invalid_argument);
  EXPECT_THROW(adroit_mpc::JointList::named(m, {"knee"}), std::invalid_argument);
}

TEST_F(CostTerms, ControlEffortNormalisedByRangeWithCheaperSynergies) {
  adroit_mpc::ControlEffort effort;
  effort.bind(m, 2);
  ASSERT_EQ(effort.size(), 4);
  Eigen::VectorXd u(4);
  u << 5.0, 1.0, 0.5, -0.25;
  // 0.5 * 2 * ((5-0)/10)^2 + 0.5 * 2 * ((1+2)/4)^2 + 0.5 * 1 * (0.25 + 0.0625)
  EXPECT_NEAR(effort.value(u, 2.0, 1.0), 0.25 + 0.5625 + 0.15625, 1e-12);
  CostDerivatives cd;
  cd.resize(nx, 4);
  effort.addDerivatives(u, 2.0, 1.0, cd);
  const double eps = 1e-6;
  for (int i = 0; i < 4; ++i) {
    Eigen::VectorXd p = u, q = u;
    p[i] += eps;
    q[i] -= eps;
    EXPECT_NEAR(cd.lu[i], (effort.value(p, 2.0, 1.0) - effort.value(q, 2.0, 1.0)) / (2 * eps), 1e-7);
  }
  EXPECT_NEAR(cd.luu(0, 0), 2.0 / 100, 1e-15);
  EXPECT_NEAR(cd.luu(3, 3), 1.0, 1e-15);
  EXPECT_EQ((cd.luu - Eigen::MatrixXd(cd.luu.diagonal().asDiagonal())).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_THROW(effort.value(Eigen::VectorXd::Zero(3), 1, 1), std::invalid_argument);
  effort.bind(m, 0);
  EXPECT_EQ(effort.size(), 2);
}

TEST_F(CostTerms, BuffersRejectResidualsTooLarge) {
  ResidualBuffer small(m, 2);
  EXPECT_THROW(adroit_mpc::pointResidual(m, d, BodyPoint::site(m, "tip"), BodyPoint::world({0, 0, 0}), true, small),
               std::invalid_argument);
  EXPECT_THROW(BodyPoint::site(m, "nose"), std::invalid_argument);
}

TEST(InverseRightJacobian, ComposesRotations) {
  const Eigen::Vector3d e(0.4, -1.1, 0.7);
  const Eigen::Vector3d w(1e-6, -2e-6, 1.5e-6);
  auto exp = [](const Eigen::Vector3d& v) { return Eigen::Quaterniond(Eigen::AngleAxisd(v.norm(), v.normalized())); };
  const Eigen::AngleAxisd composed(exp(e) * exp(w));
  const Eigen::Vector3d log = composed.angle() * composed.axis();
  const Eigen::Vector3d predicted = e + adroit_mpc::inverseRightJacobianSO3(e) * w;
  EXPECT_LT((log - predicted).norm(), 1e-11);
  // Near zero the series branch is the identity plus half the cross product.
  const Eigen::Vector3d tiny(1e-6, 0, 0);
  EXPECT_LT((adroit_mpc::inverseRightJacobianSO3(tiny) - Eigen::Matrix3d::Identity()).norm(), 1e-6);
}

}  // namespace
