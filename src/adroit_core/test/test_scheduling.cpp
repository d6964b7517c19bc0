// runInBackground and enterFifo, each case in a forked child so that the test process keeps
// its own scheduling. The child reports through its exit status (0 = as expected).
#include <gtest/gtest.h>
#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <fstream>
#include <functional>
#include <string>
#include <thread>

#include "adroit_core/scheduling.h"

namespace {

// Runs `body` in a forked child; returns its exit code (-1: it did not exit normally).
int inChild(const std::function<int()>& body) {
  const pid_t pid = fork();
  if (pid == 0) _exit(body());
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// Exit code of a child that could not enter SCHED_FIFO (no rtprio here): the case is skipped,
// not passed.
constexpr int kFifoRefused = 77;

int threadNice() { return getpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid))); }

// "/autogroup-123 nice 7" -> 7; -100 when the kernel has no autogroup file.
int autogroupNice() {
  std::ifstream in("/proc/self/autogroup");
  std::string group, word;
  int nice = -100;
  if (in >> group >> word >> nice) return nice;
  return -100;
}

}  // namespace

TEST(Scheduling, BackgroundReachesThreadsStartedBeforeAndAfterButNotTheSessionsAutogroup) {
  const int code = inChild([] {
    if (setsid() < 0) return 10;  // this child leads its own session, as under roslaunch
    const int autogroup_before = autogroupNice();
    std::atomic<bool> go{false};
    std::atomic<int> earlier_nice{-1};
    std::thread earlier([&] {
      while (!go) std::this_thread::sleep_for(std::chrono::milliseconds(1));
      earlier_nice = threadNice();
    });
    const adroit::BackgroundResult r = adroit::runInBackground(13);
    go = true;
    earlier.join();
    int later_nice = -1;
    std::thread later([&] { later_nice = threadNice(); });
    later.join();
    if (!r.error.empty()) return 11;
    if (r.threads != 2) return 12;  // this thread and `earlier`
    if (threadNice() != 13 || earlier_nice != 13) return 13;
    if (later_nice != 13) return 14;
    if (autogroupNice() != autogroup_before) return 15;  // the session keeps its weight
    return 0;
  });
  EXPECT_EQ(code, 0);
}

TEST(Scheduling, FifoThreadKeepsItsPolicyWhenTheProcessGoesToTheBackground) {
  const int code = inChild([] {
    std::atomic<int> state{0};  // 1: FIFO entered (or refused: 3), 2: background done
    std::atomic<int> policy{-1};
    std::thread control([&] {
      state = adroit::enterFifo(1, nullptr) ? 1 : 3;
      while (state != 2) std::this_thread::sleep_for(std::chrono::milliseconds(1));
      policy = sched_getscheduler(0);
    });
    while (state == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    if (state == 3) {  // no rtprio permitted here: nothing to check
      state = 2;
      control.join();
      return kFifoRefused;
    }
    adroit::runInBackground(19);
    state = 2;
    control.join();
    return policy == SCHED_FIFO ? 0 : 50;
  });
  if (code == kFifoRefused) GTEST_SKIP() << "SCHED_FIFO not permitted here (needs root or an rtprio limit)";
  EXPECT_EQ(code, 0);
}

TEST(Scheduling, NiceOutsideTheBackgroundRangeIsRefusedAndChangesNothing) {
  const int code = inChild([] {
    const int before = threadNice();
    for (int bad : {-1, 20}) {
      const adroit::BackgroundResult r = adroit::runInBackground(bad);
      if (r.error.find("not in [0, 19]") == std::string::npos || r.threads != 0) return 30;
    }
    return threadNice() == before ? 0 : 31;
  });
  EXPECT_EQ(code, 0);
}

TEST(Scheduling, FifoIsEnteredAndLeftOrRefusedWithAReason) {
  const int code = inChild([] {
    std::string error;
    if (adroit::enterFifo(0, &error) || error.empty()) return 40;  // not a SCHED_FIFO priority
    if (sched_getscheduler(0) != SCHED_OTHER) return 41;
    error.clear();
    if (adroit::enterFifo(1, &error)) {
      if (sched_getscheduler(0) != SCHED_FIFO) return 42;
      adroit::leaveFifo();
      if (sched_getscheduler(0) != SCHED_OTHER) return 43;
    } else if (error.empty()) {
      return 44;  // refused (no rtprio limit) must say why
    }
    return 0;
  });
  EXPECT_EQ(code, 0);
}
