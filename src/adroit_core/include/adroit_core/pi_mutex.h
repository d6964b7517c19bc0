// A mutex with priority inheritance (PTHREAD_PRIO_INHERIT): while a real-time thread waits
// for it, the thread holding it runs at the waiter's priority, so a normal-priority holder
// that gets preempted cannot stall a SCHED_FIFO thread behind unrelated work (priority
// inversion). Lockable: use it with std::lock_guard / std::unique_lock.
#pragma once

#include <pthread.h>

#include <stdexcept>

namespace adroit {

class PiMutex {
 public:
  PiMutex() {
    pthread_mutexattr_t attr;
    pthread_mutexattr_init(&attr);
    const int error = pthread_mutexattr_setprotocol(&attr, PTHREAD_PRIO_INHERIT);
    if (error == 0) pthread_mutex_init(&mutex_, &attr);
    pthread_mutexattr_destroy(&attr);
    if (error != 0) throw std::runtime_error("PiMutex: priority inheritance not supported");
  }
  ~PiMutex() { pthread_mutex_destroy(&mutex_); }
  PiMutex(const PiMutex&) = delete;
  PiMutex& operator=(const PiMutex&) = delete;

  void lock() { pthread_mutex_lock(&mutex_); }
  bool try_lock() { return pthread_mutex_trylock(&mutex_) == 0; }
  void unlock() { pthread_mutex_unlock(&mutex_); }

 private:
  pthread_mutex_t mutex_;
};

}  // namespace adroit
