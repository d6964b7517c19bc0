// CPU scheduling for the nodes (Linux): SCHED_FIFO for the threads that must run on time
// (the driver's simulation and publisher threads, the pools' tick and publisher threads, the
// MPC's control loop), and a background weight for threads that may run late (the MPC's
// optimiser).
//
// Why SCHED_FIFO and not nice values: with autogroup scheduling (the default of Debian's
// kernel) a nice value only ranks a thread against the threads of its own session, and
// roslaunch starts every node in a session of its own. A node at nice 19 still gets as much
// CPU as any other node, and lowering its session's weight instead (/proc/self/autogroup)
// starves all of its threads, the ones that must keep time included, whenever anything else
// is busy. A thread that sleeps between periods under SCHED_FIFO is on time either way.
#pragma once

#include <string>
#include <vector>

namespace adroit {

// Puts the calling thread under SCHED_FIFO at `priority` (1-99). False, with the reason in
// *error, when the system does not permit it (no rtprio limit or CAP_SYS_NICE); the thread
// then keeps its normal scheduling.
bool enterFifo(int priority, std::string* error);
// Back to normal scheduling (SCHED_OTHER).
void leaveFifo();

// The ids of this process's threads (Linux thread ids, /proc/self/task), in ascending order.
std::vector<int> threadIds();
// Puts the thread `tid` of this process under SCHED_FIFO at `priority`; false, with the
// reason in *error, when the system does not permit it or the thread is gone.
bool enterFifoThread(int tid, int priority, std::string* error);
// The SCHED_FIFO priority of thread `tid` (0: another policy, -1: no such thread).
int fifoPriority(int tid);

// Lowers the calling thread to `nice` (0-19); threads it starts afterwards inherit it, the
// process's other threads keep theirs (Linux keeps a nice value per thread). Within a session
// (autogroup) a niced thread then yields to every other thread of its process at once, e.g.
// an optimiser to the threads that receive its input. False, with the reason in *error, for
// a value outside [0, 19] or when the system refuses; nothing changes then.
bool setThreadNice(int nice, std::string* error);

}  // namespace adroit
