#include "adroit_core/scheduling.h"

#include <dirent.h>
#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

namespace adroit {

bool enterFifo(int priority, std::string* error) {
  sched_param sp{};
  sp.sched_priority = priority;
  const int code = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
  if (code == 0) return true;
  if (error) *error = std::strerror(code);
  return false;
}

void leaveFifo() {
  sched_param sp{};
  pthread_setschedparam(pthread_self(), SCHED_OTHER, &sp);
}

BackgroundResult runInBackground(int nice) {
  BackgroundResult result;
  if (nice < 0 || nice > 19) {
    result.error = "nice " + std::to_string(nice) + " is not in [0, 19]";
    return result;
  }
  // Every thread: on Linux a thread id given as PRIO_PROCESS names that thread alone.
  if (DIR* tasks = opendir("/proc/self/task")) {
    while (const dirent* entry = readdir(tasks)) {
      const long tid = std::strtol(entry->d_name, nullptr, 10);
      if (tid <= 0) continue;
      if (setpriority(PRIO_PROCESS, static_cast<id_t>(tid), nice) == 0)
        ++result.threads;
      else if (result.error.empty())
        result.error = "thread " + std::to_string(tid) + ": " + std::strerror(errno);
    }
    closedir(tasks);
  } else {
    result.error = std::string("/proc/self/task: ") + std::strerror(errno);
  }
  return result;
}

}  // namespace adroit
