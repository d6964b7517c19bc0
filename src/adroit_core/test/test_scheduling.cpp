// setThreadNice and enterFifo, each case in a forked child so that the test process keeps
// its own scheduling. The child reports through its exit status (0 = as expected).
#include <gtest/gtest.h>
#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <fstream>
#include <functional>
#include <string>
#include <thread>
#include <vector>

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

TEST(Scheduling, ThreadNiceReachesTheCallerAndItsNewThreadsOnly) {
  const int code = inChild([] {
    if (setsid() < 0) return 10;  // this child leads its own session, as under roslaunch
    const int autogroup_before = autogroupNice();
    const int nice_before = threadNice();
    if (nice_before >= 13) return 16;  // the case needs a thread above 13 to start from
    std::atomic<bool> go{false};
    std::atomic<int> earlier_nice{-1};
    std::thread earlier([&] {  // e.g. roscpp's receiving threads: started before, keep their weight
      while (!go) std::this_thread::sleep_for(std::chrono::milliseconds(1));
      earlier_nice = threadNice();
    });
    std::string error;
    const bool ok = adroit::setThreadNice(13, &error);
    go = true;
    earlier.join();
    int later_nice = -1;
    std::thread later([&] { later_nice = threadNice(); });  // e.g. the optimiser's workers
    later.join();
    if (!ok || !error.empty()) return 11;
    if (threadNice() != 13) return 12;
    if (earlier_nice != nice_before) return 13;
    if (later_nice != 13) return 14;
    if (autogroupNice() != autogroup_before) return 15;  // the session keeps its weight
    return 0;
  });
  EXPECT_EQ(code, 0);
}

TEST(Scheduling, NiceOutsideTheBackgroundRangeIsRefusedAndChangesNothing) {
  const int code = inChild([] {
    const int before = threadNice();
    for (int bad : {-1, 20}) {
      std::string error;
      if (adroit::setThreadNice(bad, &error) || error.find("not in [0, 19]") == std::string::npos) return 30;
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

TEST(Scheduling, AnotherThreadIsFoundByItsIdAndPutUnderFifo) {
  const int code = inChild([] {
    const std::vector<int> before = adroit::threadIds();
    if (before.size() != 1 || before[0] != getpid()) return 50;  // the child has one thread
    std::atomic<int> tid{0};
    std::atomic<bool> stop{false};
    std::thread other([&] {  // e.g. a thread roscpp started
      tid = static_cast<int>(syscall(SYS_gettid));
      while (!stop) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    });
    while (tid == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    const std::vector<int> after = adroit::threadIds();
    int result = 0;
    std::string error;
    if (after.size() != 2 || after[1] != tid) {
      result = 51;
    } else if (adroit::fifoPriority(tid) != 0) {
      result = 52;
    } else if (adroit::enterFifoThread(tid, 2, &error)) {
      if (adroit::fifoPriority(tid) != 2) result = 53;
      if (adroit::fifoPriority(getpid()) != 0) result = 54;  // the caller keeps its scheduling
    } else if (error.empty()) {
      result = 55;  // refused (no rtprio limit) must say why
    }
    stop = true;
    other.join();
    // join() returns once the thread has cleared its id; the kernel drops the task a moment
    // later (seen under ASan: still there right after join).
    for (int i = 0; i < 1000 && adroit::fifoPriority(tid) != -1; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    if (result == 0 && adroit::fifoPriority(tid) != -1) result = 56;  // gone
    error.clear();
    if (result == 0 && (adroit::enterFifoThread(tid, 2, &error) || error.empty())) result = 57;
    return result;
  });
  EXPECT_EQ(code, 0);
}
