// machine_slowdown: how much slower than its own best the machine computed while something else
// ran (adroit_core/slowdown_probe.h). Runs until SIGINT/SIGTERM or --seconds, then prints the
// summary and one line a test can parse:
//   slowdown_over_2x_fraction <fraction of the samples that took over twice the fastest>
//   longest_stall_ms <the longest the probe waited past a wake-up: the machine froze>
// The real-time integration tests run it beside the judged window: a failure while the
// machine itself ran at half speed or worse is the machine's, not the stack's.
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <thread>

#include "adroit_core/command_line.h"
#include "adroit_core/slowdown_probe.h"

namespace {
std::atomic<bool> stop_requested{false};
void onSignal(int) { stop_requested = true; }
}  // namespace

int main(int argc, char** argv) {
  double seconds = 0, period = 0.005;
  long long priority = 99;
  adroit::CommandLine args(argc, argv, "usage: machine_slowdown [--seconds S (0: until SIGINT)] [--period S] [--priority P]");
  while (args.next()) {
    if (args.is("--seconds")) seconds = args.number();
    else if (args.is("--period")) period = args.number();
    else if (args.is("--priority")) priority = args.integer();
    else args.unknown();
  }
  if (seconds < 0 || !(period >= 0.001 && period <= 1.0) || priority < 1 || priority > 99)
    args.fail("--seconds >= 0, --period in [0.001, 1] s, --priority in 1..99");
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);

  adroit::SlowdownProbe probe(static_cast<int>(priority), period);
  const auto start = std::chrono::steady_clock::now();
  while (!stop_requested.load() &&
         (seconds == 0 || std::chrono::steady_clock::now() - start < std::chrono::duration<double>(seconds)))
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  probe.stop();
  if (probe.slowdowns().count() == 0) {
    std::printf("machine_slowdown: no samples (SCHED_FIFO %lld refused: %s)\n", priority, probe.refusal().c_str());
    return 1;
  }
  const adroit::Summary s = probe.slowdowns().summary();
  std::printf("machine_slowdown: %zu samples every %.0f ms under SCHED_FIFO %lld: median %.2f / p99 %.2f / max %.2f x "
              "the fastest; %.1f %% of them over 2x; longest stall %.1f ms\n",
              s.count, period * 1e3, priority, s.median, s.p99, s.max,
              100.0 * adroit::fractionAbove(probe.slowdowns(), 2.0), probe.longestStall() * 1e3);
  std::printf("slowdown_over_2x_fraction %.4f\n", adroit::fractionAbove(probe.slowdowns(), 2.0));
  std::printf("longest_stall_ms %.2f\n", probe.longestStall() * 1e3);
  return 0;
}
