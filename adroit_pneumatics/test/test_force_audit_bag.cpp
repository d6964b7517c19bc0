// force_tracking_audit on bags written here with the rosbag API: the RMSE it reports is the
// error put into the bag, references are interpolated at the state stamps, and bad input
// (no reference, a malformed reference, a missing bag) gives a clear error, not a crash.
#include <sys/stat.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <rosbag/bag.h>

#include <adroit_msgs/ActuatorStates.h>
#include <adroit_msgs/ForceReference.h>

#include "adroit_core/run_program.h"
#include "adroit_description/scenes.h"

namespace {

constexpr double kAtm = 101325.0;
const std::vector<std::string> kNames = {"A_FFJ2_flex", "A_FFJ2_ext", "A_THJ4_flex"};

struct AuditRun {
  int status = -1;
  std::string out;
};

AuditRun audit(const std::string& bag, const std::vector<std::string>& extra = {}) {
  adroit::ProgramOptions options;
  options.timeout_s = 60;
  options.capture_output = true;
  options.merge_stderr = true;
  std::vector<std::string> args = {FORCE_AUDIT_BINARY, "--bag", bag, "--model",
                                   adroit::description::sceneFile(ADROIT_DESCRIPTION_SHARE, "arm_hand")};
  args.insert(args.end(), extra.begin(), extra.end());
  const auto run = adroit::runProgram(args, options);
  AuditRun r;
  r.out = run.output;
  r.status = run.exit_code;
  return r;
}

// RMSE column of a group's row ("  FF  1.00  ..."), NaN when absent.
double rmseOf(const std::string& out, const std::string& group) {
  std::istringstream in(out);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream row(line);
    std::string g;
    double rmse;
    if (row >> g >> rmse && g == group) return rmse;
  }
  return std::nan("");
}

// The desired tension of cylinder j at time t of the test's reference: a ramp per cylinder.
double desired(std::size_t j, double t) { return 5.0 + 2.0 * j + 10.0 * t; }

// A bag of one reference (stamp 100 s, dt 10 ms, 101 knots: the ramps) and states every
// 4 ms from 100.002 s whose tension is desired + offset[j]; the states name a cylinder the
// reference lacks (ignored) and come in another column order than the reference.
void writeBag(const std::string& path, const std::vector<double>& offset, bool with_reference, bool malformed) {
  rosbag::Bag bag(path, rosbag::bagmode::Write);
  const ros::Time t0(100.0);
  if (with_reference) {
    adroit_msgs::ForceReference ref;
    ref.header.stamp = t0;
    ref.dt = 0.01;
    ref.steps = 101;
    ref.name = kNames;
    for (std::uint32_t k = 0; k < ref.steps; ++k)
      for (std::size_t j = 0; j < kNames.size(); ++j) ref.force.push_back(desired(j, k * ref.dt));
    if (malformed) {
      adroit_msgs::ForceReference bad = ref;
      bad.force.pop_back();
      bag.write("/adroit/force_reference", t0, bad);
    }
    bag.write("/adroit/force_reference", t0, ref);
  }
  const double bore[] = {M_PI * 0.009 * 0.009 / 4, M_PI * 0.009 * 0.009 / 4, M_PI * 0.009 * 0.009 / 4};
  for (int i = 0; i < 200; ++i) {
    const double t = 0.002 + 0.004 * i;
    adroit_msgs::ActuatorStates s;
    s.header.stamp = t0 + ros::Duration(t);
    s.name = {"A_THJ4_flex", "A_MFJ2_flex", "A_FFJ2_ext", "A_FFJ2_flex"};
    const std::size_t order[] = {2, 99, 1, 0};
    for (std::size_t j : order) {
      const double f = j == 99 ? 1.0 : desired(j, t) + offset[j];
      s.force.push_back(f);
      s.pressure.push_back(kAtm + f / bore[j == 99 ? 0 : j]);
      s.length.push_back(0.01);
      s.length_rate.push_back(0.0);
      s.command.push_back(0.0);
    }
    s.supply_pressure = 620e3;
    bag.write("/adroit/actuator_states", s.header.stamp, s);
  }
  bag.close();
}

std::string tempBag(const char* name) { return ::testing::TempDir() + name; }

}  // namespace

TEST(ForceAuditBag, ReportsTheErrorInTheBag) {
  const std::string exact = tempBag("audit_exact.bag"), off = tempBag("audit_offset.bag");
  writeBag(exact, {0.0, 0.0, 0.0}, true, false);
  writeBag(off, {1.0, -1.0, 0.5}, true, false);
  const AuditRun a = audit(exact), b = audit(off);
  ASSERT_EQ(a.status, 0) << a.out;
  ASSERT_EQ(b.status, 0) << b.out;
  // Desired interpolated between knots at the state stamps: the ramps are matched exactly.
  EXPECT_NEAR(rmseOf(a.out, "FF"), 0.0, 0.005) << a.out;
  EXPECT_NEAR(rmseOf(a.out, "TH"), 0.0, 0.005) << a.out;
  // Offsets of +1 and -1 N in FF (RMSE 1), 0.5 N in TH; the cylinder without a reference
  // (MF) is not audited.
  EXPECT_NEAR(rmseOf(b.out, "FF"), 1.0, 0.005) << b.out;
  EXPECT_NEAR(rmseOf(b.out, "TH"), 0.5, 0.005) << b.out;
  EXPECT_TRUE(std::isnan(rmseOf(b.out, "MF"))) << b.out;
  EXPECT_NE(b.out.find("200 actuator states audited"), std::string::npos) << b.out;
  // The figure per finger group against its 0.5 N target, the floor beside it; one
  // reference over the whole run: its preview is the reference as it came.
  EXPECT_NE(a.out.find("RESULT adroit_pneumatics/demo_force_rmse_FF 0.00 N target <= 0.5 PASS"), std::string::npos)
      << a.out;
  EXPECT_NE(b.out.find("RESULT adroit_pneumatics/demo_force_rmse_FF 1.00 N target <= 0.5 FAIL"), std::string::npos)
      << b.out;
  EXPECT_NE(b.out.find("bound: the plant's floor on this run"), std::string::npos) << b.out;
  EXPECT_NE(a.out.find("0.00 / 0.00 / 0.00"), std::string::npos) << a.out;
  // The ramps rise 10 N/s: 0.1 N from one 10 ms knot to the next; the ratio to the floor read
  // through the sensor is a RESULT of its own.
  EXPECT_NE(a.out.find("the plans' tension step per knot: largest 0.1 N, 99th percentile 0.1 N; the floor read through "
                       "the sensor"),
            std::string::npos) << a.out;
  EXPECT_NE(b.out.find("RESULT adroit_pneumatics/demo_force_floor_ratio_FF "), std::string::npos) << b.out;
  const AuditRun exact_floor = audit(off, {"--floor-sensor", "none"});
  EXPECT_EQ(exact_floor.status, 0) << exact_floor.out;
  EXPECT_NE(exact_floor.out.find("the floor exact"), std::string::npos) << exact_floor.out;
}

TEST(ForceAuditBag, BadInputIsAClearError) {
  const std::string none = tempBag("audit_none.bag"), bad = tempBag("audit_bad.bag");
  writeBag(none, {0.0, 0.0, 0.0}, false, false);
  writeBag(bad, {0.0, 0.0, 0.0}, true, true);
  const AuditRun a = audit(none);
  EXPECT_EQ(a.status, 1) << a.out;
  EXPECT_NE(a.out.find("no actuator state inside a force reference"), std::string::npos) << a.out;
  const AuditRun b = audit(bad);  // the malformed reference is counted and skipped, the good one used
  EXPECT_EQ(b.status, 0) << b.out;
  EXPECT_NE(b.out.find("(1 unusable)"), std::string::npos) << b.out;
  const AuditRun sensor = audit(bad, {"--floor-sensor", "noisy"});
  EXPECT_EQ(sensor.status, 2) << sensor.out;
  EXPECT_NE(sensor.out.find("force_tracking_audit: --floor-sensor must be sim or none (got 'noisy')"), std::string::npos)
      << sensor.out;
  const AuditRun c = audit(tempBag("no_such.bag"));
  EXPECT_EQ(c.status, 1) << c.out;
  EXPECT_NE(c.out.find("force_tracking_audit: "), std::string::npos) << c.out;
}

// A FIFO named as the bag would block rosbag's open for good: refused before it is opened
// (audit() kills the program after its timeout, which fails the status check).
TEST(ForceAuditBag, AFifoIsRefusedNotWaitedOn) {
  const std::string fifo = tempBag("audit_fifo.bag");
  unlink(fifo.c_str());
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  const AuditRun r = audit(fifo);
  EXPECT_EQ(r.status, 1) << r.out;
  EXPECT_NE(r.out.find(fifo + ": not a regular file (a FIFO)"), std::string::npos) << r.out;
  unlink(fifo.c_str());
}
