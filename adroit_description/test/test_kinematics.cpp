// The URDF and the MJCF describe the same robot: urdfdom parses it, joints agree, and KDL's
// forward kinematics on the URDF matches MuJoCo's for every link at random configurations.
// Zero-pose fingertips match the kinematics reference.
#include <gtest/gtest.h>

#include <kdl/frames.hpp>
#include <kdl/treefksolverpos_recursive.hpp>
#include <kdl_parser/kdl_parser.hpp>
#include <random>
#include <urdf_parser/urdf_parser.h>

#include "adroit_core/model_tables.h"
#include "test_helpers.h"

namespace {

std::string urdfPath(const std::string& scene) {
  return adroit::description::urdfFile(adroit_test::shareDir(), scene);
}

TEST(Urdf, ParsesAndJointsMatchMjcf) {
  for (const auto& facts : adroit_test::expectedScenes()) {
    SCOPED_TRACE(facts.name);
    urdf::ModelInterfaceSharedPtr urdf = urdf::parseURDFFile(urdfPath(facts.name));
    ASSERT_TRUE(urdf) << "urdfdom failed to parse " << urdfPath(facts.name);
    auto loaded = adroit_test::loadScene(facts.name);
    const mjModel* m = loaded.model.get();
    int revolute = 0;
    for (const auto& [name, joint] : urdf->joints_) {
      if (joint->type != urdf::Joint::REVOLUTE) continue;
      ++revolute;
      const int j = mj_name2id(m, mjOBJ_JOINT, name.c_str());
      ASSERT_GE(j, 0) << name;
      EXPECT_NEAR(joint->limits->lower, m->jnt_range[2 * j], 1e-9) << name;
      EXPECT_NEAR(joint->limits->upper, m->jnt_range[2 * j + 1], 1e-9) << name;
      const double* axis = m->jnt_axis + 3 * j;
      EXPECT_NEAR(joint->axis.x, axis[0], 1e-6) << name;
      EXPECT_NEAR(joint->axis.y, axis[1], 1e-6) << name;
      EXPECT_NEAR(joint->axis.z, axis[2], 1e-6) << name;
    }
    EXPECT_EQ(revolute, facts.arm ? 28 : 24);
  }
}

TEST(Urdf, KdlForwardKinematicsMatchesMujoco) {
  std::mt19937 rng(7);
  for (const auto& facts : adroit_test::expectedScenes()) {
    SCOPED_TRACE(facts.name);
    KDL::Tree tree;
    ASSERT_TRUE(kdl_parser::treeFromFile(urdfPath(facts.name), tree));
    KDL::TreeFkSolverPos_recursive fk(tree);
    auto loaded = adroit_test::loadScene(facts.name);
    const mjModel* m = loaded.model.get();
    adroit::DataPtr d = adroit::makeData(m);

    // KDL joint index of every MuJoCo hinge.
    std::vector<std::pair<int, unsigned>> joint_map;  // (mujoco joint, kdl q_nr)
    for (const auto& [seg_name, element] : tree.getSegments()) {
      const KDL::Joint& kj = element.segment.getJoint();
      if (kj.getType() == KDL::Joint::None) continue;
      const int j = mj_name2id(m, mjOBJ_JOINT, kj.getName().c_str());
      ASSERT_GE(j, 0) << kj.getName();
      joint_map.emplace_back(j, element.q_nr);
    }
    ASSERT_EQ(joint_map.size(), tree.getNrOfJoints());

    int compared = 0;
    double worst_pos = 0, worst_rot = 0;
    for (int sample = 0; sample < 100; ++sample) {
      mj_resetData(m, d.get());
      KDL::JntArray q(tree.getNrOfJoints());
      for (auto [j, qnr] : joint_map) {
        std::uniform_real_distribution<double> u(m->jnt_range[2 * j], m->jnt_range[2 * j + 1]);
        const double v = u(rng);
        d->qpos[m->jnt_qposadr[j]] = v;
        q(qnr) = v;
      }
      mj_kinematics(m, d.get());
      // Teleop scenes: the URDF's floating base joint is KDL's identity; the base's pose in
      // the world is the free joint's (the driver broadcasts it).
      KDL::Frame base_pose = KDL::Frame::Identity();
      if (facts.free_base) {
        const int root = mj_name2id(m, mjOBJ_BODY, "forearm");
        ASSERT_GE(root, 0);
        const double* r = d->xmat + 9 * root;
        base_pose = KDL::Frame(KDL::Rotation(r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8]),
                               KDL::Vector(d->xpos[3 * root], d->xpos[3 * root + 1], d->xpos[3 * root + 2]));
      }
      for (const auto& [seg_name, element] : tree.getSegments()) {
        const int b = mj_name2id(m, mjOBJ_BODY, seg_name.c_str());
        ASSERT_GE(b, 0) << "URDF link without a MuJoCo body: " << seg_name;
        KDL::Frame f;
        ASSERT_GE(fk.JntToCart(q, f, seg_name), 0) << seg_name;
        if (seg_name != "world") f = base_pose * f;
        for (int k = 0; k < 3; ++k) worst_pos = std::max(worst_pos, std::abs(f.p(k) - d->xpos[3 * b + k]));
        // Rotation error: angle of R_kdl^T R_mujoco.
        KDL::Rotation r_mj(d->xmat[9 * b + 0], d->xmat[9 * b + 1], d->xmat[9 * b + 2], d->xmat[9 * b + 3],
                           d->xmat[9 * b + 4], d->xmat[9 * b + 5], d->xmat[9 * b + 6], d->xmat[9 * b + 7],
                           d->xmat[9 * b + 8]);
        KDL::Vector axis;
        worst_rot = std::max(worst_rot, (f.M.Inverse() * r_mj).GetRotAngle(axis));
        ++compared;
      }
    }
    // Every link of the URDF (the root included) has a MuJoCo body of the same name.
    EXPECT_EQ(compared, 100 * static_cast<int>(tree.getSegments().size()));
    EXPECT_LT(worst_pos, 1e-6);
    EXPECT_LT(worst_rot, 1e-6);
  }
}

// Kinematics reference section 1e: zero-pose tip sites in the palm frame (origin = WRJ0 pivot).
TEST(Kinematics, ZeroPoseFingertipsMatchReference) {
  const std::vector<std::pair<std::string, std::array<double, 3>>> tips = {
      {"S_fftip", {0.033, 0, 0.191}},   {"S_mftip", {0.011, 0, 0.195}},      {"S_rftip", {-0.011, 0, 0.191}},
      {"S_lftip", {-0.034, 0, 0.184}}, {"S_thtip", {0.1029, -0.009, 0.0980}}};
  for (const char* scene : {"hand", "arm_hand", "tube"}) {
    SCOPED_TRACE(scene);
    auto loaded = adroit_test::loadScene(scene);
    const mjModel* m = loaded.model.get();
    adroit::DataPtr d = adroit::makeData(m);
    mj_kinematics(m, d.get());
    const int palm = mj_name2id(m, mjOBJ_BODY, "palm");
    ASSERT_GE(palm, 0);
    for (const auto& [site, expected] : tips) {
      const int s = mj_name2id(m, mjOBJ_SITE, site.c_str());
      ASSERT_GE(s, 0) << site;
      double rel[3], local[3];
      mju_sub3(rel, d->site_xpos + 3 * s, d->xpos + 3 * palm);
      mju_mulMatTVec(local, d->xmat + 9 * palm, rel, 3, 3);
      for (int k = 0; k < 3; ++k) EXPECT_NEAR(local[k], expected[k], 1e-3) << site << " axis " << k;
    }
  }
}

}  // namespace
