#include "adroit_driver/can_frame.h"

#include <cstdio>
#include <cstring>

// Where the kernel's header exists, our copy of the layout must agree with it bit for bit.
#if defined(__has_include)
#if __has_include(<linux/can.h>)
#include <linux/can.h>
#define ADROIT_HAVE_LINUX_CAN_H 1
#endif
#endif

namespace adroit::driver::can {

#ifdef ADROIT_HAVE_LINUX_CAN_H
static_assert(sizeof(struct can_frame) == sizeof(CanFrame), "size differs from struct can_frame");
static_assert(offsetof(struct can_frame, can_id) == offsetof(CanFrame, id), "can_id offset differs");
static_assert(offsetof(struct can_frame, can_dlc) == offsetof(CanFrame, dlc), "can_dlc offset differs");
static_assert(offsetof(struct can_frame, data) == offsetof(CanFrame, data), "data offset differs");
static_assert(CAN_EFF_FLAG == kEffFlag && CAN_RTR_FLAG == kRtrFlag && CAN_ERR_FLAG == kErrFlag, "flag bits differ");
static_assert(CAN_SFF_MASK == kSffMask && CAN_EFF_MASK == kEffMask && CAN_ERR_MASK == kErrMask, "masks differ");
static_assert(CAN_MAX_DLEN == kMaxDataLength, "payload size differs");
#endif

CanFrame makeFrame(std::uint32_t id, const std::uint8_t* bytes, std::size_t length) {
  CanFrame f;
  f.id = id;
  f.dlc = static_cast<std::uint8_t>(length < kMaxDataLength ? length : kMaxDataLength);
  if (f.dlc > 0) std::memcpy(f.data, bytes, f.dlc);
  return f;
}

bool sameFrame(const CanFrame& a, const CanFrame& b) {
  if (a.id != b.id || a.dlc != b.dlc) return false;
  const std::size_t n = a.dlc < kMaxDataLength ? a.dlc : kMaxDataLength;
  return std::memcmp(a.data, b.data, n) == 0;
}

std::string toString(const CanFrame& frame) {
  char text[64];
  int n;
  if (isErrorFrame(frame)) {
    n = std::snprintf(text, sizeof text, "ERR#%08X:", static_cast<unsigned>(frame.id & kErrMask));
  } else if (isExtended(frame)) {
    n = std::snprintf(text, sizeof text, "%08X#", static_cast<unsigned>(frame.id & kEffMask));
  } else {
    n = std::snprintf(text, sizeof text, "%03X#", static_cast<unsigned>(frame.id & kSffMask));
  }
  std::string out(text, static_cast<std::size_t>(n));
  if (isRemote(frame) && !isErrorFrame(frame)) return out + "R";
  const std::size_t length = frame.dlc < kMaxDataLength ? frame.dlc : kMaxDataLength;
  for (std::size_t k = 0; k < length; ++k) {
    std::snprintf(text, sizeof text, "%02X", frame.data[k]);
    out += text;
  }
  if (frame.dlc > kMaxDataLength) out += " (dlc " + std::to_string(frame.dlc) + ")";
  return out;
}

}  // namespace adroit::driver::can
