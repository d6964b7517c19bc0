// CPU scheduling for the nodes (Linux): SCHED_FIFO for the threads that must run on time
// (the driver's simulation and publisher threads, the pools' tick and publisher threads, the
// MPC's control loop), and a background weight for a whole process whose other threads may
// run late (the MPC's optimiser).
//
// Why SCHED_FIFO and not nice values: with autogroup scheduling (the default of Debian's
// kernel) a nice value only ranks a thread against the threads of its own session, and
// roslaunch starts every node in a session of its own. A node at nice 19 still gets as much
// CPU as any other node, and lowering its session's weight instead (/proc/self/autogroup)
// starves all of its threads, the ones that must keep time included, whenever anything else
// is busy. A thread that sleeps between periods under SCHED_FIFO is on time either way.
#pragma once

#include <string>

namespace adroit {

// Puts the calling thread under SCHED_FIFO at `priority` (1-99). False, with the reason in
// *error, when the system does not permit it (no rtprio limit or CAP_SYS_NICE); the thread
// then keeps its normal scheduling.
bool enterFifo(int priority, std::string* error);
// Back to normal scheduling (SCHED_OTHER).
void leaveFifo();

// What runInBackground did.
struct BackgroundResult {
  int threads = 0;    // threads set to the nice value (every thread of the process)
  std::string error;  // empty when every thread was set
};

// Lowers the whole process to `nice` (0-19): every thread it has now (Linux keeps a nice
// value per thread, so the launch-prefix `nice` and setpriority(PRIO_PROCESS, getpid())
// reach only the main thread's descendants) and, through inheritance, every thread they
// start. Threads under SCHED_FIFO are unaffected.
BackgroundResult runInBackground(int nice);

}  // namespace adroit
