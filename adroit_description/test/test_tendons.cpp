// Tendon routing: every cylinder pulls its joint in the direction of its role with the
// moment arm of the kinematics reference, and the DIP follows the PIP through the soft
// coupling constraint (thesis 6.3).
#include <gtest/gtest.h>

#include <map>
#include <random>

#include "adroit_core/model_tables.h"
#include "adroit_description/cylinders.h"
#include "test_helpers.h"

namespace {

bool isFingerPip(const std::string& joint) {
  return joint == "FFJ1" || joint == "MFJ1" || joint == "RFJ1" || joint == "LFJ1";
}

// Kinematics reference, "Antagonist tendon pairs" table: moment arm per joint [m]. The arm
// has no published moment arms (0 = not checked).
double referenceMomentArm(const std::string& joint) {
  if (joint.rfind("AR", 0) == 0) return 0.0;
  if (joint.rfind("WR", 0) == 0) return 0.018;
  if (joint == "THJ4") return 0.01636;
  if (joint == "THJ2" || joint == "THJ1") return 0.011;
  if (joint == "THJ0") return 0.009;
  if (isFingerPip(joint)) return 0.00805;  // xFJ1 tendons on J1
  return 0.010;  // xFJ3, xFJ2, LFJ4, THJ3
}

// Direction of flexion: positive angle for every joint except THJ0, whose range is
// -90..0 deg with negative = IP flexion (kinematics reference 1d).
int flexionSign(const std::string& joint) { return joint == "THJ0" ? -1 : 1; }

struct Role {
  std::string joint;
  int sign;  // sign of the joint torque a pulling cylinder must produce
};

Role roleOf(const std::string& actuator) {  // A_<joint>_<flex|ext>
  const auto last = actuator.find_last_of('_');
  const std::string joint = actuator.substr(2, last - 2);
  const bool flex = actuator.substr(last + 1) == "flex";
  return {joint, flex ? flexionSign(joint) : -flexionSign(joint)};
}

TEST(Tendons, PullDirectionMatchesRoleEverywhere) {
  std::mt19937 rng(11);
  auto loaded = adroit_test::loadScene("arm_hand");
  const mjModel* m = loaded.model.get();
  adroit::DataPtr d = adroit::makeData(m);
  adroit::ModelTables t(m);
  for (int sample = 0; sample < 200; ++sample) {
    mj_resetData(m, d.get());
    for (int j = 0; j < m->njnt; ++j) {
      std::uniform_real_distribution<double> u(m->jnt_range[2 * j], m->jnt_range[2 * j + 1]);
      d->qpos[m->jnt_qposadr[j]] = sample == 0 ? 0.0 : u(rng);
    }
    mj_fwdPosition(m, d.get());
    mj_fwdVelocity(m, d.get());  // actuator_moment is computed in mj_transmission (fwdPosition)
    for (int a = 0; a < m->nu; ++a) {
      const std::string name = t.actuators.name(a);
      const Role role = roleOf(name);
      const int dof = m->jnt_dofadr[t.joints.at(role.joint)];
      // qfrc = actuator_moment * tension, tension >= 0.
      const double moment = d->actuator_moment[a * m->nv + dof];
      ASSERT_GT(moment * role.sign, 0) << name << " at sample " << sample;
      if (sample == 0) {
        if (referenceMomentArm(role.joint) > 0) {
          EXPECT_NEAR(std::abs(moment), referenceMomentArm(role.joint), 0.15 * referenceMomentArm(role.joint))
              << name;
        }
        // A cylinder acts on its own joint only, except the finger J1 tendons, which
        // also cross the DIP (J0) with the distal moment arm 0.00705.
        for (int j = 0; j < m->njnt; ++j) {
          const std::string other = t.joints.name(j);
          if (other == role.joint) continue;
          const double off = d->actuator_moment[a * m->nv + m->jnt_dofadr[j]];
          const bool dip_of_j1 = isFingerPip(role.joint) && other == role.joint.substr(0, 3) + "0";
          if (dip_of_j1) {
            EXPECT_NEAR(off, moment * 0.00705 / 0.00805, 0.15 * 0.00705) << name << " on " << other;
          } else {
            EXPECT_NEAR(off, 0.0, 1e-9) << name << " on " << other;
          }
        }
      }
    }
  }
}

TEST(Tendons, PistonTravelStaysWithinStroke) {
  auto loaded = adroit_test::loadScene("arm_hand");
  const mjModel* m = loaded.model.get();
  const auto cylinders = adroit::description::cylinderTable(m);
  adroit::DataPtr d = adroit::makeData(m);
  std::mt19937 rng(3);
  for (int sample = 0; sample < 100; ++sample) {
    for (int j = 0; j < m->njnt; ++j) {
      std::uniform_real_distribution<double> u(m->jnt_range[2 * j], m->jnt_range[2 * j + 1]);
      d->qpos[m->jnt_qposadr[j]] = u(rng);
    }
    mj_fwdPosition(m, d.get());
    for (const auto& c : cylinders) {
      const double raw = c.longest_tendon_length - d->ten_length[c.tendon];
      EXPECT_GE(raw, -1e-6) << c.name;  // never longer than the computed longest length
      EXPECT_LE(raw, c.stroke) << c.name;
    }
  }
}

class Coupling : public ::testing::TestWithParam<std::string> {};

// Drive the PIP alone with a joint torque (gravity off so nothing else moves the finger):
// the DIP follows inside the band of the coupler tendon, q0 in 1.1418 q1 +- 0.1418
// (kinematics reference section 2), while without the coupler it would not move at all.
TEST_P(Coupling, DipFollowsPip) {
  const std::string finger = GetParam();
  auto loaded = adroit_test::loadScene("hand");
  mjModel* m = loaded.model.get();
  m->opt.gravity[2] = 0;
  adroit::ModelTables t(m);
  const int pip = m->jnt_dofadr[t.joints.at(finger + "J1")];
  const int dip = m->jnt_dofadr[t.joints.at(finger + "J0")];
  const int q_pip = m->jnt_qposadr[t.joints.at(finger + "J1")];
  const int q_dip = m->jnt_qposadr[t.joints.at(finger + "J0")];

  auto simulate = [&](bool coupled, double* worst_band_violation) {
    m->tendon_limited[t.tendons.at("T_" + finger + "J1c")] = coupled;
    adroit::DataPtr d = adroit::makeData(m);
    *worst_band_violation = 0;
    for (int i = 0; i < 1500; ++i) {  // 3 s: a slow sine sweep of the PIP torque
      d->qfrc_applied[pip] = 0.02 * (1.0 - std::cos(2 * M_PI * 0.5 * d->time));
      mj_step(m, d.get());
      const double q1 = d->qpos[q_pip], q0 = d->qpos[q_dip];
      const double centre = std::min(1.571, std::max(0.0, 1.1418 * q1));
      const double violation = std::abs(q0 - centre) - 0.1418;
      if (i > 50) *worst_band_violation = std::max(*worst_band_violation, violation);
    }
    return std::make_pair(d->qpos[q_pip], d->qpos[q_dip]);
  };
  (void)dip;
  double violation_coupled, violation_free;
  const auto coupled = simulate(true, &violation_coupled);
  const auto free = simulate(false, &violation_free);
  EXPECT_GT(coupled.first, 0.5) << "the PIP torque must actually bend the PIP";
  EXPECT_GT(coupled.second, 0.4) << "the DIP must follow";
  EXPECT_LT(violation_coupled, 0.05) << "soft constraint: small excursions outside the band only";
  EXPECT_LT(std::abs(free.second), 0.2) << "without the coupler the DIP stays near its start";
  EXPECT_GT(violation_free, 0.2);
}

INSTANTIATE_TEST_SUITE_P(Fingers, Coupling, ::testing::Values("FF", "MF", "RF", "LF"));

}  // namespace
