// One classical CAN frame, laid out exactly like Linux's `struct can_frame` (16 bytes), so
// a frame read from a PF_CAN raw socket, or carried as one datagram over a Unix-domain
// seqpacket socket, is copied as is. Defined here (not taken from <linux/can.h>) so that
// the protocol code also builds where that header is absent; where it is present,
// can_frame.cpp checks that both layouts and flag values agree.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace adroit::driver::can {

// Flag bits of CanFrame::id (Linux canid_t).
constexpr std::uint32_t kEffFlag = 0x80000000u;  // 29-bit extended identifier
constexpr std::uint32_t kRtrFlag = 0x40000000u;  // remote transmission request
constexpr std::uint32_t kErrFlag = 0x20000000u;  // error frame made by the controller/driver
constexpr std::uint32_t kSffMask = 0x000007FFu;  // 11-bit standard identifier
constexpr std::uint32_t kEffMask = 0x1FFFFFFFu;  // 29-bit extended identifier
constexpr std::uint32_t kErrMask = 0x1FFFFFFFu;  // error class bits of an error frame
constexpr std::size_t kMaxDataLength = 8;

struct CanFrame {
  std::uint32_t id = 0;        // identifier and flag bits
  std::uint8_t dlc = 0;        // payload length, 0..8
  std::uint8_t pad = 0;        // Linux: __pad
  std::uint8_t res0 = 0;       // Linux: __res0
  std::uint8_t len8_dlc = 0;   // Linux: DLC 9..15 of an 8-byte frame (unused here)
  alignas(8) std::uint8_t data[kMaxDataLength] = {};
};

static_assert(sizeof(CanFrame) == 16, "CanFrame must match struct can_frame (16 bytes)");
static_assert(offsetof(CanFrame, id) == 0, "can_id at byte 0");
static_assert(offsetof(CanFrame, dlc) == 4, "len/can_dlc at byte 4");
static_assert(offsetof(CanFrame, len8_dlc) == 7, "len8_dlc at byte 7");
static_assert(offsetof(CanFrame, data) == 8, "data at byte 8");

inline bool isExtended(const CanFrame& f) { return (f.id & kEffFlag) != 0; }
inline bool isRemote(const CanFrame& f) { return (f.id & kRtrFlag) != 0; }
inline bool isErrorFrame(const CanFrame& f) { return (f.id & kErrFlag) != 0; }
// A classical data frame with an 11-bit identifier: the only kind the ADROIT protocol uses.
inline bool isStandardData(const CanFrame& f) { return (f.id & (kEffFlag | kRtrFlag | kErrFlag)) == 0; }
inline std::uint32_t standardId(const CanFrame& f) { return f.id & kSffMask; }

// A standard data frame; bytes beyond `length` (at most 8) are zero.
CanFrame makeFrame(std::uint32_t id, const std::uint8_t* bytes, std::size_t length);

// Same identifier (with flags), same length and same payload bytes (bytes beyond dlc and the
// padding bytes are not part of the frame on the wire and are ignored).
bool sameFrame(const CanFrame& a, const CanFrame& b);

// candump's notation, for logs: "123#0102AB", "1F334455#", "123#R", "ERR#20000004:0004..."
std::string toString(const CanFrame& frame);

}  // namespace adroit::driver::can
