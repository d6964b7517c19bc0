// CPU scheduling for the nodes (Linux): SCHED_FIFO for the threads that must run on time
// (the driver's simulation and publisher threads, the pools' tick and publisher threads),
// and a background weight for whole processes that may run late (the behaviour MPC).
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
  int threads = 0;         // threads set to the nice value (every thread of the process)
  bool autogroup = false;  // the session's autogroup was set too
  std::string error;       // empty when everything that applies was done
};

// Lowers the whole process to `nice` (0-19): every thread it has now (Linux keeps a nice
// value per thread) and, through inheritance, every thread they start. With autogroup
// scheduling (the default on desktop and Debian kernels) a nice value only ranks a thread
// against threads of its own session: roslaunch starts every node in a session of its own,
// so a niced node would still get as much CPU as each real-time-critical node. When this
// process leads its session, the session's autogroup gets the same nice value, which ranks
// the node below the others. A process that does not lead its session (a node started from
// a shell) leaves the autogroup alone: it is shared with the shell and whatever else runs there.
BackgroundResult runInBackground(int nice);

}  // namespace adroit
