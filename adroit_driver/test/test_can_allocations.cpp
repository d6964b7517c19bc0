// Encoding, decoding, sequence tracking and reading/writing frames allocate nothing: the
// driver does them in its 500 Hz loop (DESIGN.md §2). This binary counts the calls of the
// global operator new made while a test holds a counting window.
#include <gtest/gtest.h>
#include <sys/socket.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <new>

#include "adroit_driver/can_protocol.h"
#include "adroit_driver/can_transport.h"

#include "allocation_window.h"

namespace adroit::driver::can {
namespace {

TEST(CanAllocations, CodecsTrackerAndTransportAllocateNothing) {
  int fds[2];
  ASSERT_EQ(socketpair(AF_UNIX, SOCK_SEQPACKET, 0, fds), 0);
  CanTransport a(fds[0]), b(fds[1]);
  CanFrame in[8];
  SequenceTracker tracker;
  Message message;

  allocation_window::start();
  for (int cycle = 0; cycle < 100; ++cycle) {
    const auto seq = static_cast<std::uint8_t>(cycle);
    CanFrame f;
    JointAnglesFrame joints{4, {0.1, -0.2, 1.5, std::nan("")}, seq};
    ValveCommandFrame valves{2, 3, 3, {-5.0, 0.0, 9.0}, seq};
    SensorFrame pressure{1, SensorKind::kPressure, 4, {101325, 620e3, 2e6, 0}, seq};
    HeartbeatFrame heartbeat{kPalmNode, kProtocolVersion, NodeState::kOperational, 0, seq};
    EstopFrame estop{kHostNode, EstopAction::kEngage, EstopCause::kOperator, seq};
    FaultFrame fault{valveBoardNode(1), FaultCode::kCommandTimeout, 3, 50, seq};
    const Message messages[] = {joints, valves, pressure, heartbeat, estop, fault};
    for (const Message& m : messages) {
      ASSERT_TRUE(encode(m, &f).ok());
      ASSERT_EQ(decode(f, &message), DecodeError::kNone);
      ASSERT_EQ(a.write(f), IoStatus::kOk);
    }
    tracker.observe(seq);
    const ReadResult r = b.read(in, 8, std::chrono::milliseconds(100));
    ASSERT_EQ(r.count, 6u);
  }
  EXPECT_EQ(allocation_window::stop(), 0u);
}

}  // namespace
}  // namespace adroit::driver::can
