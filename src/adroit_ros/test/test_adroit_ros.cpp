// adroit_ros against a real master: parameters of each type, the one-line errors, scene
// resolution, the diagnostics builder, the rejection counters and the real-time path (roscpp's
// threads and a callback queue under SCHED_FIFO).
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sched.h>
#include <std_msgs/Int32.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "adroit_ros/diagnostics.h"
#include "adroit_ros/params.h"
#include "adroit_ros/realtime.h"
#include "adroit_core/scheduling.h"

using adroit::rosutil::ParameterError;
using adroit::rosutil::Params;

namespace {

// The error's text, or "" if none was thrown.
template <typename F>
std::string errorOf(F f) {
  try {
    f();
  } catch (const ParameterError& e) {
    return e.what();
  }
  return "";
}

class ParamsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    pnh_.deleteParam("");
  }
  ros::NodeHandle pnh_{"~p"};
};

TEST_F(ParamsTest, ReadsEachTypeAndFallsBack) {
  pnh_.setParam("rate", 200);  // an integer is a number too
  pnh_.setParam("gain", 0.5);
  pnh_.setParam("steps", 7);
  pnh_.setParam("on", true);
  pnh_.setParam("mode", std::string("force"));
  pnh_.setParam("names", std::vector<std::string>{"a", "b"});
  const Params p(pnh_);
  EXPECT_EQ(p.number("rate", 1.0), 200.0);
  EXPECT_EQ(p.number("gain", 1.0), 0.5);
  EXPECT_EQ(p.number("absent", 3.25), 3.25);
  EXPECT_EQ(p.integer("steps", 1), 7);
  EXPECT_TRUE(p.boolean("on", false));
  EXPECT_EQ(p.string("mode", "x"), "force");
  EXPECT_EQ(p.strings("names"), (std::vector<std::string>{"a", "b"}));
  EXPECT_TRUE(p.strings("absent").empty());
}

TEST_F(ParamsTest, WrongTypeAndRangeNameTheParameter) {
  pnh_.setParam("rate", std::string("fast"));
  pnh_.setParam("steps", 2.5);
  pnh_.setParam("on", 1);
  pnh_.setParam("gain", -1.0);
  pnh_.setParam("names", std::vector<int>{1, 2});
  const Params p(pnh_);
  const std::string full = pnh_.getNamespace();
  EXPECT_EQ(errorOf([&] { p.number("rate", 1); }), "bad parameter " + full + "/rate: expected a number");
  EXPECT_EQ(errorOf([&] { p.integer("steps", 1); }), "bad parameter " + full + "/steps: expected an integer");
  EXPECT_EQ(errorOf([&] { p.boolean("on", true); }), "bad parameter " + full + "/on: expected true or false");
  EXPECT_EQ(errorOf([&] { p.number("gain", 1, 0, 10); }), "bad parameter " + full + "/gain: must be in [0, 10], got -1");
  EXPECT_EQ(errorOf([&] { p.integer("absent", 11, 0, 10); }),
            "bad parameter " + full + "/absent: must be in [0, 10], got 11");
  EXPECT_NE(errorOf([&] { p.strings("names"); }).find("/names: expected a list of names"), std::string::npos);
}

TEST_F(ParamsTest, UnknownKeysAreRefused) {
  pnh_.setParam("rate", 1.0);
  pnh_.setParam("ilqg/horizon", 10);
  pnh_.setParam("ilqg/horizn", 10);
  const Params p(pnh_);
  EXPECT_EQ(errorOf([&] { p.checkKeys("", {"rate", "ilqg"}); }), "");
  EXPECT_EQ(errorOf([&] { p.checkKeys("", {"ilqg"}); }), "bad parameter " + pnh_.getNamespace() + "/rate: unknown parameter");
  EXPECT_EQ(errorOf([&] { p.checkKeys("ilqg", {"horizon"}); }),
            "bad parameter " + pnh_.getNamespace() + "/ilqg/horizn: unknown parameter (did you mean horizon?)");
}

TEST_F(ParamsTest, ModelPathFromSceneOrFile) {
  const Params p(pnh_);
  const std::string hand = p.modelPath("hand");
  EXPECT_NE(hand.find("/mjcf/hand.xml"), std::string::npos) << hand;
  EXPECT_NE(p.modelPath("keypad", true).find("/mjcf/keypad_planning.xml"), std::string::npos);
  pnh_.setParam("scene", std::string("moon"));
  const std::string error = errorOf([&] { p.modelPath("hand"); });
  EXPECT_EQ(error.rfind("bad parameter " + pnh_.getNamespace() + "/scene: ", 0), 0u) << error;
  EXPECT_NE(error.find("moon"), std::string::npos) << error;
  pnh_.setParam("model_file", std::string("/some/model.xml"));
  EXPECT_EQ(p.modelPath("hand"), "/some/model.xml");
}

TEST(StatusBuilder, LevelOnlyRisesAndValuesAreFormatted) {
  adroit::rosutil::StatusBuilder s("node", "hw");
  s.add("count", std::uint64_t{42});
  s.add("ratio", 0.25);
  s.add("ok", true);
  s.add("mode", "force");
  s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "first warning");
  s.raise(diagnostic_msgs::DiagnosticStatus::WARN, "second warning");
  s.raise(diagnostic_msgs::DiagnosticStatus::OK, "fine");
  EXPECT_EQ(s.status().level, diagnostic_msgs::DiagnosticStatus::WARN);
  EXPECT_EQ(s.status().message, "first warning");
  s.raise(diagnostic_msgs::DiagnosticStatus::ERROR, "broken");
  EXPECT_EQ(s.status().message, "broken");
  ASSERT_EQ(s.status().values.size(), 4u);
  EXPECT_EQ(s.status().values[0].value, "42");
  EXPECT_EQ(s.status().values[1].value, "0.25");
  EXPECT_EQ(s.status().values[2].value, "true");
  EXPECT_EQ(s.status().values[3].value, "force");
}

TEST(RejectionCounters, CountsExactlyFromSeveralThreads) {
  adroit::rosutil::RejectionCounters c({"not_finite", "unknown_name"});
  auto work = [&c](std::size_t reason, int n) {
    for (int i = 0; i < n; ++i) c.count(reason);
  };
  std::thread a(work, 0, 100000), b(work, 1, 50000), d(work, 0, 100000);
  a.join(), b.join(), d.join();
  EXPECT_EQ(c.get(0), 200000u);
  EXPECT_EQ(c.get(1), 50000u);
  EXPECT_EQ(c.total(), 250000u);
  adroit::rosutil::StatusBuilder s("n", "h");
  c.addTo(s, "rejected");
  ASSERT_EQ(s.status().values.size(), 3u);
  EXPECT_EQ(s.status().values[0].key, "rejected_total");
  EXPECT_EQ(s.status().values[0].value, "250000");
  EXPECT_EQ(s.status().values[2].key, "rejected_unknown_name");
  EXPECT_EQ(s.status().values[2].value, "50000");
}

// Threads of this process under SCHED_FIFO at `priority`.
int threadsAtFifo(int priority) {
  int n = 0;
  for (int id : adroit::threadIds()) n += adroit::fifoPriority(id) == priority;
  return n;
}

// The test needs SCHED_FIFO (root, or an rtprio limit): without it the refusal must say why.
bool fifoPermitted() {
  std::string error;
  std::thread probe([&] { adroit::enterFifo(1, &error); });
  probe.join();
  return error.empty();
}

TEST(RealtimePath, RoscppsThreadsGoUnderFifoAndTheCallerKeepsItsScheduling) {
  std::string error;
  const bool ok = adroit::rosutil::fifoRosThreads(7, &error);
  if (!fifoPermitted()) {
    EXPECT_FALSE(ok);
    EXPECT_FALSE(error.empty());
    return;
  }
  ASSERT_TRUE(ok) << error;
  // The socket poll thread, the XML-RPC server, rosout's publisher, the internal queue.
  EXPECT_GE(threadsAtFifo(7), 3);
  EXPECT_EQ(adroit::fifoPriority(static_cast<int>(syscall(SYS_gettid))), 0);
  // Messages still flow (through the now real-time poll thread).
  ros::NodeHandle nh;
  std::atomic<int> got{0};
  ros::Subscriber sub = nh.subscribe<std_msgs::Int32>("rt_ping", 10, [&](const std_msgs::Int32::ConstPtr& m) { got = m->data; });
  ros::Publisher pub = nh.advertise<std_msgs::Int32>("rt_ping", 10);
  std_msgs::Int32 m;
  m.data = 42;
  for (int i = 0; i < 200 && got != 42; ++i) {
    pub.publish(m);
    ros::spinOnce();
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(got, 42);
}

TEST(RealtimePath, AFifoQueueRunsItsCallbacksOnItsOwnThreadUnderFifo) {
  adroit::rosutil::FifoCallbackQueue fifo;
  EXPECT_EQ(fifo.priority(), -1);
  fifo.start(9);
  ros::NodeHandle nh;
  nh.setCallbackQueue(fifo.queue());
  std::atomic<int> policy{-1}, priority{-1}, got{0};
  std::atomic<long> caller{0};
  ros::Subscriber sub = nh.subscribe<std_msgs::Int32>("rt_queue", 10, [&](const std_msgs::Int32::ConstPtr& m) {
    policy = sched_getscheduler(0);
    priority = adroit::fifoPriority(static_cast<int>(syscall(SYS_gettid)));
    caller = syscall(SYS_gettid);
    got = m->data;
  });
  ros::NodeHandle plain;
  ros::Publisher pub = plain.advertise<std_msgs::Int32>("rt_queue", 10);
  std_msgs::Int32 m;
  m.data = 7;
  for (int i = 0; i < 200 && got != 7; ++i) {  // nobody spins the global queue: the queue's own thread runs it
    pub.publish(m);
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(got, 7);
  EXPECT_NE(caller, syscall(SYS_gettid));
  if (fifoPermitted()) {
    EXPECT_EQ(fifo.priority(), 9);
    EXPECT_EQ(policy, SCHED_FIFO);
    EXPECT_EQ(priority, 9);
    EXPECT_TRUE(fifo.refusal().empty());
  } else {
    EXPECT_EQ(fifo.priority(), 0);
    EXPECT_FALSE(fifo.refusal().empty());
  }
  sub.shutdown();
  const auto start = std::chrono::steady_clock::now();
  {
    adroit::rosutil::FifoCallbackQueue normal;  // priority 0: normal scheduling, joined at once
    normal.start(0);
    while (normal.priority() < 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    EXPECT_EQ(normal.priority(), 0);
    EXPECT_TRUE(normal.refusal().empty());
  }
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::milliseconds(500));
}

}  // namespace

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_adroit_ros");
  adroit::rosutil::startRos();  // before the first NodeHandle: roscpp's threads are known
  ros::NodeHandle nh;  // keeps the node up for the tests
  return RUN_ALL_TESTS();
}
