// libFuzzer harness: arbitrary bytes as CAN frames for every decoder, and as datagrams of
// any size through the transport's receive path. Properties checked (a violation traps):
//  * a frame any decoder accepts re-encodes to exactly the same bytes;
//  * the generic decoder accepts a frame exactly when one typed decoder does;
//  * every datagram sent to a CanTransport is accounted for once: a data frame returned,
//    or counted as wrong size, impossible length or error frame.
// Build and run: docs/can_protocol.md, "Fuzzing".
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstring>

#include "adroit_driver/can_protocol.h"
#include "adroit_driver/can_transport.h"

using namespace adroit::driver::can;

namespace {

void check(bool ok) {
  if (!ok) __builtin_trap();
}

template <class T>
int decodeAs(const CanFrame& f) {
  T m;
  if (decode(f, &m) != DecodeError::kNone) return 0;
  CanFrame again;
  check(encode(m, &again).ok());
  check(sameFrame(f, again));
  return 1;
}

void decodeFrame(const CanFrame& f, SequenceTracker* tracker) {
  const int typed = decodeAs<JointAnglesFrame>(f) + decodeAs<TouchFrame>(f) + decodeAs<ValveCommandFrame>(f) +
                    decodeAs<SensorFrame>(f) + decodeAs<SupplyFrame>(f) + decodeAs<HeartbeatFrame>(f) +
                    decodeAs<EstopFrame>(f) + decodeAs<FaultFrame>(f);
  check(typed <= 1);
  Message m;
  const DecodeError error = decode(f, &m);
  check(decodeErrorName(error) != nullptr);
  check((error == DecodeError::kNone) == (typed == 1));
  if (error == DecodeError::kNone) {
    CanFrame again;
    check(encode(m, &again).ok());
    check(sameFrame(f, again));
    tracker->observe(f.data[0]);
  }
  (void)toString(f);
}

// One socketpair for the whole run: side 0 sends raw datagrams, side 1 is read by a transport.
struct Link {
  int sender = -1;
  CanTransport* reader = nullptr;
  Link() {
    int fds[2];
    check(socketpair(AF_UNIX, SOCK_SEQPACKET, 0, fds) == 0);
    sender = fds[0];
    reader = new CanTransport(fds[1], "fuzz");  // lives for the whole process
  }
};

std::uint64_t accounted(const TransportCounters& c) {
  return c.frames_read + c.wrong_size + c.bad_dlc + c.error_frames;
}

void drain(CanTransport* t) {
  CanFrame frames[64];
  for (;;) {
    const ReadResult r = t->read(frames, 64, std::chrono::nanoseconds(0));
    check(r.status == IoStatus::kOk || r.status == IoStatus::kTimeout);
    check(r.count <= 64);
    for (std::size_t k = 0; k < r.count; ++k) check(frames[k].dlc <= kMaxDataLength && !isErrorFrame(frames[k]));
    if (r.status == IoStatus::kTimeout) return;
  }
}

// Chunks of the input (length byte % 33, then that many bytes) as datagrams.
void throughTransport(const std::uint8_t* data, std::size_t size) {
  static Link link;
  const std::uint64_t before = accounted(link.reader->counters());
  std::uint64_t sent = 0;
  std::size_t i = 0;
  for (int chunk = 0; chunk < 64 && i < size; ++chunk) {
    std::size_t length = data[i++] % 33;
    if (length > size - i) length = size - i;
    if (::send(link.sender, data + i, length, MSG_DONTWAIT) == static_cast<ssize_t>(length)) ++sent;
    i += length;
    if (chunk % 16 == 15) drain(link.reader);  // keep the socket buffer from filling
  }
  drain(link.reader);
  check(accounted(link.reader->counters()) - before == sent);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  SequenceTracker tracker;
  // Every 16 bytes as one CanFrame, exactly as a datagram would be taken.
  for (std::size_t at = 0; at + sizeof(CanFrame) <= size; at += sizeof(CanFrame)) {
    CanFrame f;
    std::memcpy(static_cast<void*>(&f), data + at, sizeof f);
    decodeFrame(f, &tracker);  // the decoders must cope with any bytes, dlc > 8 included
    CanFrame parsed;
    switch (parseDatagram(data + at, sizeof f, &parsed)) {
      case DatagramKind::kDataFrame: check(parsed.dlc <= kMaxDataLength); break;
      case DatagramKind::kErrorFrame: (void)classifyErrorFrame(parsed); break;
      case DatagramKind::kWrongSize: check(false); break;
      case DatagramKind::kBadDlc: check(f.dlc > kMaxDataLength); break;
    }
  }
  CanFrame whole;
  check((parseDatagram(data, size, &whole) == DatagramKind::kWrongSize) == (size != sizeof(CanFrame)));
  check(tracker.stats().frames >= tracker.stats().duplicates);
  throughTransport(data, size);
  return 0;
}
