#include "adroit_core/scheduling.h"

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <dirent.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

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

std::vector<int> threadIds() {
  std::vector<int> ids;
  DIR* dir = opendir("/proc/self/task");
  if (!dir) return ids;
  while (const dirent* entry = readdir(dir)) {
    char* end = nullptr;
    const long id = std::strtol(entry->d_name, &end, 10);
    if (end != entry->d_name && *end == '\0') ids.push_back(static_cast<int>(id));
  }
  closedir(dir);
  std::sort(ids.begin(), ids.end());
  return ids;
}

bool enterFifoThread(int tid, int priority, std::string* error) {
  sched_param sp{};
  sp.sched_priority = priority;
  // On Linux, sched_setscheduler with a thread id sets that one thread.
  if (sched_setscheduler(tid, SCHED_FIFO, &sp) == 0) return true;
  if (error) *error = std::strerror(errno);
  return false;
}

int fifoPriority(int tid) {
  const int policy = sched_getscheduler(tid);
  if (policy < 0) return -1;
  if (policy != SCHED_FIFO) return 0;
  sched_param sp{};
  return sched_getparam(tid, &sp) == 0 ? sp.sched_priority : -1;
}

bool setThreadNice(int nice, std::string* error) {
  if (nice < 0 || nice > 19) {
    if (error) *error = "nice " + std::to_string(nice) + " is not in [0, 19]";
    return false;
  }
  // On Linux a thread id given as PRIO_PROCESS names that thread alone.
  if (setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), nice) == 0) return true;
  if (error) *error = std::strerror(errno);
  return false;
}

}  // namespace adroit
