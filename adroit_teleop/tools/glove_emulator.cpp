// glove_emulator: a CyberGlove on a pseudo-terminal, so the glove driver can be run and
// tested without the hardware. It links --link (default /tmp/adroit_glove) to the pty's
// slave device; the driver opens that path like a real port. The protocol is answered by
// adroit_teleop's GloveEmulator (docs/glove_protocol.md); this file only does the I/O, the
// pacing on CLOCK_MONOTONIC and the fault injection that needs the device (unplugging).
//
//   glove_emulator                                  # 22 sensors, synthetic motion, 120 Hz
//   glove_emulator --sensors 18 --rate 500 --log /tmp/glove.log
//   glove_emulator --trajectory recorded.csv --garbage-every 50 --unplug-after 5 --unplug-for 2
//   glove_emulator --trajectory motion.csv --start-on-signal   # first row until SIGUSR1, then play
//
// --realtime-priority P streams under SCHED_FIFO P (it sleeps in ppoll between records): a real
// glove streams from its own processor whatever the host does, and at normal scheduling the
// emulator missed its deadlines for 100 ms on a busy 2-core machine, long enough for the
// teleop node to call the glove stale.
//
// Exit status: 0 after SIGINT/SIGTERM or --duration, 2 for bad options or a bad trajectory
// file (message names the file and line), 1 when the pseudo-terminal cannot be set up.
#include <adroit_core/command_line.h>
#include <adroit_core/scheduling.h>
#include <adroit_teleop/glove_emulator.h>
#include <adroit_teleop/pseudo_terminal.h>
#include <poll.h>
#include <signal.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

using namespace adroit::teleop;

namespace {

const char* kUsage =
    "usage: glove_emulator [--link PATH] [--sensors 18|22] [--rate HZ] [--trajectory synthetic|FILE.csv]\n"
    "                      [--period S] [--garbage-every K] [--unplug-after S --unplug-for S] [--glove-error]\n"
    "                      [--log FILE] [--seed N] [--duration S] [--realtime-priority P] [--start-on-signal]";

volatile sig_atomic_t g_stop = 0;
void onSignal(int) { g_stop = 1; }
volatile sig_atomic_t g_start_motion = 0;  // SIGUSR1 with --start-on-signal
void onStartSignal(int) { g_start_motion = 1; }

timespec monotonicNow() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts;
}

double secondsSince(const timespec& start) {
  const timespec now = monotonicNow();
  return (now.tv_sec - start.tv_sec) + 1e-9 * (now.tv_nsec - start.tv_nsec);
}

// start + s, rounded up to the next nanosecond so a wake-up is never before the deadline.
timespec after(const timespec& start, double s) {
  const long long ns = start.tv_nsec + static_cast<long long>(std::ceil(std::max(s, 0.0) * 1e9));
  timespec ts{};
  ts.tv_sec = start.tv_sec + ns / 1000000000LL;
  ts.tv_nsec = ns % 1000000000LL;
  return ts;
}

long long realtimeNs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

}  // namespace

int main(int argc, char** argv) {
  std::string link = "/tmp/adroit_glove", trajectory = "synthetic", log_path;
  double period = 4, unplug_after = 0, unplug_for = 0, duration = 0;
  int realtime_priority = 0;
  bool start_on_signal = false;
  EmulatorOptions options;
  // roslaunch appends its remappings (__name:=..., __log:=...): not options of ours.
  std::vector<char*> kept;
  for (int i = 0; i < argc; ++i)
    if (i == 0 || std::strstr(argv[i], ":=") == nullptr) kept.push_back(argv[i]);
  adroit::CommandLine args(static_cast<int>(kept.size()), kept.data(), kUsage);
  while (args.next()) {
    if (args.is("--link")) link = args.text();
    else if (args.is("--sensors")) options.sensors = static_cast<int>(args.integer());
    else if (args.is("--rate")) options.rate_hz = args.number();
    else if (args.is("--trajectory")) trajectory = args.text();
    else if (args.is("--period")) period = args.number();
    else if (args.is("--garbage-every")) options.garbage_every = static_cast<int>(args.integer());
    else if (args.is("--unplug-after")) unplug_after = args.number();
    else if (args.is("--unplug-for")) unplug_for = args.number();
    else if (args.is("--glove-error")) options.glove_error = true;
    else if (args.is("--log")) log_path = args.text();
    else if (args.is("--seed")) options.seed = static_cast<std::uint32_t>(args.integer());
    else if (args.is("--duration")) duration = args.number();
    else if (args.is("--realtime-priority")) realtime_priority = static_cast<int>(args.integer());
    else if (args.is("--start-on-signal")) start_on_signal = true;
    else args.unknown();
  }
  if (!validSensorCount(options.sensors)) args.fail("--sensors must be 18 or 22");
  if (!(options.rate_hz >= 1 && options.rate_hz <= 1000)) args.fail("--rate must be in 1..1000 Hz");
  if (!(period > 0)) args.fail("--period must be > 0 s");
  if (options.garbage_every < 0) args.fail("--garbage-every must be >= 0");
  if ((unplug_after > 0) != (unplug_for > 0) || unplug_after < 0 || unplug_for < 0)
    args.fail("--unplug-after and --unplug-for go together, both > 0 s");
  if (duration < 0) args.fail("--duration must be >= 0 s (0: until SIGINT/SIGTERM)");
  if (link.empty()) args.fail("--link needs a path");
  if (realtime_priority < 0 || realtime_priority > 99) args.fail("--realtime-priority must be in 0..99 (0: normal scheduling)");

  std::shared_ptr<const GloveTrajectory> motion;
  try {
    if (trajectory == "synthetic") motion = std::make_shared<SyntheticTrajectory>(options.sensors, period);
    else motion = std::make_shared<CsvTrajectory>(CsvTrajectory::load(trajectory, options.sensors));
  } catch (const TrajectoryError& e) {
    std::fprintf(stderr, "glove_emulator: %s\n", e.what());
    return 2;
  }
  std::shared_ptr<DeferredTrajectory> deferred;
  if (start_on_signal) motion = deferred = std::make_shared<DeferredTrajectory>(motion);
  GloveEmulator glove(options, motion);

  FILE* log = nullptr;
  if (!log_path.empty()) {
    log = std::fopen(log_path.c_str(), "w");
    if (!log) {
      std::fprintf(stderr, "glove_emulator: cannot write log %s: %s\n", log_path.c_str(), std::strerror(errno));
      return 2;
    }
    std::fprintf(log, "# sequence realtime_ns s1..s%d (one line per record, time taken just before its write)\n",
                 options.sensors);
  }

  // SIGINT/SIGTERM stay blocked except inside ppoll(), so a signal can never slip in between
  // checking g_stop and going to sleep.
  sigset_t blocked, wait_mask;
  sigemptyset(&blocked);
  sigaddset(&blocked, SIGINT);
  sigaddset(&blocked, SIGTERM);
  sigprocmask(SIG_BLOCK, &blocked, &wait_mask);
  sigdelset(&wait_mask, SIGINT);
  sigdelset(&wait_mask, SIGTERM);
  struct sigaction sa {};
  sa.sa_handler = onSignal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  if (start_on_signal) {  // SIGUSR1 may arrive any time: it only sets a flag the loop reads
    struct sigaction start_action {};
    start_action.sa_handler = onStartSignal;
    sigaction(SIGUSR1, &start_action, nullptr);
  }

  std::unique_ptr<PseudoTerminal> pty;
  try {
    pty = std::make_unique<PseudoTerminal>(link);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "glove_emulator: %s\n", e.what());
    return 1;
  }
  std::printf("glove_emulator: %d sensors on %s, link %s, streaming at %g Hz\n", options.sensors,
              pty->slaveName().c_str(), link.c_str(), options.rate_hz);
  std::fflush(stdout);

  std::string refused;
  if (realtime_priority > 0 && !adroit::enterFifo(realtime_priority, &refused))
    std::fprintf(stderr, "glove_emulator: --realtime-priority %d: SCHED_FIFO not permitted (%s); streaming at normal "
                 "scheduling\n", realtime_priority, refused.c_str());

  const timespec start = monotonicNow();
  bool unplugged = false, replugged = false;
  double replug_at = 0;
  unsigned long long dropped_bytes = 0;
  EmulatorOutput out;
  std::uint8_t input[256];

  while (!g_stop) {
    double now = secondsSince(start);
    if (duration > 0 && now >= duration) break;
    if (deferred && g_start_motion && !deferred->started()) {
      deferred->start(now);
      std::printf("glove_emulator: motion started at %.3f s\n", now);
      std::fflush(stdout);
    }
    if (unplug_after > 0 && !unplugged && !replugged && now >= unplug_after) {
      pty.reset();  // the driver's reads see a hang-up; the link disappears
      glove.reset();
      unplugged = true;
      replug_at = now + unplug_for;
      std::printf("glove_emulator: unplugged for %g s\n", unplug_for);
      std::fflush(stdout);
    }
    if (unplugged && now >= replug_at) {
      try {
        pty = std::make_unique<PseudoTerminal>(link);
      } catch (const std::exception& e) {
        std::fprintf(stderr, "glove_emulator: %s\n", e.what());
        return 1;
      }
      unplugged = false;
      replugged = true;
      std::printf("glove_emulator: plugged in again on %s\n", pty->slaveName().c_str());
      std::fflush(stdout);
    }

    // Next wake-up: a stream deadline, an unplug event, the end, or a 100 ms heartbeat.
    double wake = now + 0.1;
    if (duration > 0) wake = std::min(wake, duration);
    if (unplug_after > 0 && !replugged) wake = std::min(wake, unplugged ? replug_at : unplug_after);
    const bool streaming = pty && glove.streaming();
    if (streaming) wake = std::min(wake, glove.nextDeadline());

    // Wait for host bytes until just before a stream deadline, then sleep to the deadline
    // itself on an absolute time (clock_nanosleep's resolution, not ppoll's). ppoll runs in
    // every pass, with no wait after a deadline sleep, so at rates whose period is shorter
    // than the slack commands and signals still get in.
    constexpr double kSlack = 0.002;
    double wait = std::max(0.0, wake - now - (streaming ? kSlack : 0.0));
    if (streaming && wake - now <= kSlack) {
      const timespec at = after(start, wake);
      while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, nullptr) == EINTR) {
      }
      wait = 0;
    }
    const timespec timeout{static_cast<time_t>(wait), static_cast<long>((wait - std::floor(wait)) * 1e9)};
    pollfd p{pty ? pty->master() : -1, POLLIN, 0};
    if (ppoll(&p, 1, &timeout, &wait_mask) > 0 && (p.revents & POLLIN)) {
      const ssize_t n = read(p.fd, input, sizeof input);
      if (n > 0) glove.receive(input, static_cast<std::size_t>(n), secondsSince(start), out);
    }
    if (pty) glove.tick(secondsSince(start), out);

    if (!out.bytes.empty() && pty) {
      const long long written_at = realtimeNs();
      // Non-blocking: when nobody reads the port its buffer fills and the rest is lost, as
      // on a serial line with nothing listening.
      const ssize_t n = write(pty->master(), out.bytes.data(), out.bytes.size());
      dropped_bytes += out.bytes.size() - static_cast<std::size_t>(std::max<ssize_t>(n, 0));
      if (log) {
        for (const SentRecord& rec : out.records) {
          std::fprintf(log, "%llu %lld", static_cast<unsigned long long>(rec.sequence), written_at);
          for (int i = 0; i < rec.count; ++i) std::fprintf(log, " %u", rec.values[i]);
          std::fputc('\n', log);
        }
      }
    }
    out.clear();
  }

  pty.reset();  // removes the link
  if (log) std::fclose(log);
  const EmulatorStats& s = glove.stats();
  std::printf("glove_emulator: sent %llu polled and %llu streamed records, %llu error replies, %llu garbage bytes; "
              "%llu missed deadlines, %llu bytes dropped (nobody reading)\n",
              static_cast<unsigned long long>(s.polled_records), static_cast<unsigned long long>(s.streamed_records),
              static_cast<unsigned long long>(s.error_replies), static_cast<unsigned long long>(s.garbage_bytes),
              static_cast<unsigned long long>(s.missed_deadlines), dropped_bytes);
  return 0;
}
