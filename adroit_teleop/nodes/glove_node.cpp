// CyberGlove driver node: reads the glove (GloveDriver) on its own thread and publishes every
// record on /adroit_teleop/glove (adroit_msgs/GloveSensors, stamped with its arrival on the
// serial line), whether the glove is stale on /adroit_teleop/glove_stale (latched, on change),
// and diagnostics (link state, rates, rejected frames) at 1 Hz.
//
// Private parameters: ~port (required: no silent default for a hardware port), ~baud
// (115200), ~sensors (0 = ask the glove), ~mode (stream | poll), ~poll_rate (Hz),
// ~stale_after (s), ~retry_min / ~retry_max (s, reconnection back-off).
#include <ros/ros.h>

#include <atomic>
#include <mutex>
#include <thread>

#include <adroit_msgs/GloveSensors.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <std_msgs/Bool.h>

#include "adroit_ros/diagnostics.h"
#include "adroit_core/scheduling.h"
#include "adroit_ros/node_main.h"
#include "adroit_ros/params.h"
#include "adroit_teleop/glove_driver.h"

namespace adroit::teleop {

namespace {

GloveDriverConfig readConfig(const rosutil::Params& p) {
  p.checkKeys("", {"port", "baud", "sensors", "mode", "poll_rate", "stale_after", "retry_min", "retry_max",
                   "realtime_priority"});
  GloveDriverConfig c;
  c.port = p.string("port", "");
  if (c.port.empty()) p.fail("port", "is required: the glove's serial device (or the emulator's link)");
  c.baud = p.integer("baud", c.baud);
  if (!baudRateSupported(c.baud)) p.fail("baud", std::to_string(c.baud) + " is not a supported rate");
  c.sensors = p.integer("sensors", c.sensors);
  if (c.sensors != 0 && !validSensorCount(c.sensors)) p.fail("sensors", "must be 18, 22 or 0 (ask the glove)");
  const std::string mode = p.string("mode", "stream");
  if (mode != "stream" && mode != "poll") p.fail("mode", "must be stream or poll, got '" + mode + "'");
  c.stream = mode == "stream";
  c.poll_rate = p.number("poll_rate", c.poll_rate, 1.0, 1000.0);
  c.stale_after = p.number("stale_after", c.stale_after, 0.005, 10.0);
  c.retry_min = p.number("retry_min", c.retry_min, 0.01, 60.0);
  c.retry_max = p.number("retry_max", c.retry_max, c.retry_min, 600.0);
  return c;
}

const char* stateName(GloveDriver::State s) {
  switch (s) {
    case GloveDriver::State::kDisconnected: return "disconnected";
    case GloveDriver::State::kQuerying: return "querying sensor count";
    case GloveDriver::State::kRunning: return "running";
  }
  return "?";
}

class GloveNode {
 public:
  GloveNode(ros::NodeHandle nh, ros::NodeHandle pnh)
      : driver_(readConfig(rosutil::Params(pnh))),
        // The reading thread and roscpp's threads under SCHED_FIFO (adroit_ros/realtime.h): the
        // records are the teleop's command path. 0 = normal scheduling.
        realtime_priority_(rosutil::Params(pnh).integer("realtime_priority", 16, 0, 98)) {
    ros::NodeHandle io(nh, "adroit_teleop");
    glove_pub_ = io.advertise<adroit_msgs::GloveSensors>("glove", 50);
    stale_pub_ = io.advertise<std_msgs::Bool>("glove_stale", 1, true);
    diag_pub_ = nh.advertise<diagnostic_msgs::DiagnosticArray>("/adroit/diagnostics", 5);
    diag_timer_ = nh.createWallTimer(ros::WallDuration(1.0), &GloveNode::onDiagnostics, this);
    std::string error;
    if (realtime_priority_ > 0 && !rosutil::fifoRosThreads(realtime_priority_, &error))
      ROS_WARN("adroit_teleop glove: roscpp's threads keep normal scheduling (%s)", error.c_str());
    thread_ = std::thread(&GloveNode::loop, this);
  }
  ~GloveNode() {
    running_ = false;
    if (thread_.joinable()) thread_.join();
  }

 private:
  void loop() {
    std::string why;
    if (realtime_priority_ > 0 && !enterFifo(realtime_priority_, &why))
      ROS_WARN("adroit_teleop glove: ~realtime_priority %d: SCHED_FIFO not permitted (%s); reading at normal "
               "scheduling", realtime_priority_, why.c_str());
    std::vector<GloveDriver::Record> records;
    adroit_msgs::GloveSensors msg;
    bool stale_published = false, stale_known = false;
    std::string reported;
    while (running_ && ros::ok()) {
      records.clear();
      GloveDriver::State state;
      std::string error;
      bool stale;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        driver_.spinOnce(std::chrono::milliseconds(10), records);
        state = driver_.state();
        error = driver_.lastError();
        stale = driver_.stale();
        received_ += records.size();
      }
      // The records came with the read that just returned: now, in ROS time, is their arrival
      // (less the few microseconds since, measured on the steady clock).
      const auto steady_now = GloveDriver::Clock::now();
      const ros::Time ros_now = ros::Time::now();
      for (const auto& r : records) {
        msg.header.stamp = ros_now - ros::Duration(std::chrono::duration<double>(steady_now - r.arrival).count());
        msg.record = static_cast<std::uint32_t>(r.frame.sequence);
        msg.raw.assign(r.frame.raw.begin(), r.frame.raw.begin() + r.frame.count);
        glove_pub_.publish(msg);
      }
      if (!stale_known || stale != stale_published) {
        std_msgs::Bool b;
        b.data = stale;
        stale_pub_.publish(b);
        stale_published = stale;
        stale_known = true;
        if (stale)
          ROS_WARN("adroit_teleop glove: stale (%s): %s", stateName(state), error.empty() ? "no record" : error.c_str());
        else
          ROS_INFO("adroit_teleop glove: records flowing (%d sensors)", driver_.sensors());
      }
      if (!error.empty() && error != reported) {
        ROS_ERROR_THROTTLE(5.0, "adroit_teleop glove: %s (retrying every <= %.1f s)", error.c_str(), driver_.retryDelay());
        reported = error;
      } else if (error.empty()) {
        reported.clear();
      }
    }
    std::lock_guard<std::mutex> lock(mutex_);
    driver_.close();
  }

  void onDiagnostics(const ros::WallTimerEvent&) {
    rosutil::StatusBuilder s("adroit_teleop: glove", "cyberglove");
    std::lock_guard<std::mutex> lock(mutex_);
    const ParserStats& p = driver_.parserStats();
    s.add("state", stateName(driver_.state()));
    s.add("stale", driver_.stale());
    s.add("sensors", driver_.sensors());
    s.add("records", p.records);
    s.add("record_rate_hz", static_cast<double>(received_ - received_at_last_));
    s.add("garbage_bytes", p.garbage_bytes);
    s.add("rejected_frames", p.rejectedTotal());
    for (int r = 0; r < kRejectReasons; ++r)
      s.add(std::string("rejected_") + rejectReasonName(static_cast<RejectReason>(r)), p.rejected[r]);
    s.add("glove_error_records", p.error_records);
    s.add("connects", driver_.connects());
    s.add("disconnects", driver_.disconnects());
    s.add("last_error", driver_.lastError());
    received_at_last_ = received_;
    if (driver_.stale())
      s.raise(diagnostic_msgs::DiagnosticStatus::ERROR,
              driver_.lastError().empty() ? "glove stale" : "glove stale: " + driver_.lastError());
    s.publish(diag_pub_);
  }

  GloveDriver driver_;
  std::mutex mutex_;  // driver_ between the reading thread and diagnostics
  std::uint64_t received_ = 0, received_at_last_ = 0;
  ros::Publisher glove_pub_, stale_pub_, diag_pub_;
  ros::WallTimer diag_timer_;
  int realtime_priority_;
  std::atomic<bool> running_{true};
  std::thread thread_;
};

}  // namespace
}  // namespace adroit::teleop

int main(int argc, char** argv) {
  return adroit::rosutil::runNode<adroit::teleop::GloveNode>(argc, argv, "glove", 1);
}
