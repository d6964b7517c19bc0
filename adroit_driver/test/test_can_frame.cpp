// CanFrame: the same bytes as Linux's struct can_frame, helpers and the candump notation.
#include <gtest/gtest.h>

#include <cstring>

#include "adroit_driver/can_frame.h"

#if __has_include(<linux/can.h>)
#include <linux/can.h>
#define HAVE_LINUX_CAN_H 1
#endif

namespace adroit::driver::can {
namespace {

TEST(CanFrame, HasTheLinuxLayout) {
  EXPECT_EQ(sizeof(CanFrame), 16u);
  EXPECT_EQ(alignof(CanFrame), 8u);
  CanFrame f;
  f.id = 0x12345678;
  f.dlc = 3;
  f.data[0] = 0xAA;
  f.data[7] = 0xBB;
  unsigned char bytes[16];
  std::memcpy(bytes, &f, sizeof f);
  EXPECT_EQ(bytes[0], 0x78);  // little-endian host: the id's low byte first
  EXPECT_EQ(bytes[4], 3);
  EXPECT_EQ(bytes[8], 0xAA);
  EXPECT_EQ(bytes[15], 0xBB);
}

#ifdef HAVE_LINUX_CAN_H
TEST(CanFrame, CopiesToAndFromStructCanFrame) {
  struct can_frame k;
  std::memset(&k, 0, sizeof k);
  k.can_id = 0x123 | CAN_RTR_FLAG;
  k.can_dlc = 2;
  k.data[0] = 1;
  k.data[1] = 2;
  CanFrame f;
  std::memcpy(static_cast<void*>(&f), &k, sizeof f);
  EXPECT_EQ(f.id, 0x123u | kRtrFlag);
  EXPECT_EQ(f.dlc, 2);
  EXPECT_EQ(f.data[1], 2);
  EXPECT_TRUE(isRemote(f));
}
#endif

TEST(CanFrame, FlagsAndIdentifier) {
  CanFrame f;
  f.id = 0x7FF;
  EXPECT_TRUE(isStandardData(f));
  EXPECT_EQ(standardId(f), 0x7FFu);
  f.id = 0x1234 | kEffFlag;
  EXPECT_TRUE(isExtended(f));
  EXPECT_FALSE(isStandardData(f));
  f.id = kErrFlag | 0x40;
  EXPECT_TRUE(isErrorFrame(f));
  EXPECT_FALSE(isStandardData(f));
}

TEST(CanFrame, MakeFrameZeroesTheRestAndCapsTheLength) {
  const std::uint8_t bytes[10] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10};
  CanFrame f = makeFrame(0x100, bytes, 3);
  EXPECT_EQ(f.dlc, 3);
  EXPECT_EQ(f.data[2], 3);
  EXPECT_EQ(f.data[3], 0);
  f = makeFrame(0x100, bytes, 10);
  EXPECT_EQ(f.dlc, 8);
  EXPECT_EQ(f.data[7], 8);
}

TEST(CanFrame, SameFrameIgnoresBytesBeyondTheLength) {
  const std::uint8_t bytes[2] = {1, 2};
  CanFrame a = makeFrame(0x10, bytes, 2), b = a;
  b.data[5] = 99;  // not on the wire
  b.pad = 1;
  EXPECT_TRUE(sameFrame(a, b));
  b.data[1] = 3;
  EXPECT_FALSE(sameFrame(a, b));
  b = a;
  b.dlc = 3;
  EXPECT_FALSE(sameFrame(a, b));
}

TEST(CanFrame, ToStringUsesCandumpNotation) {
  const std::uint8_t bytes[3] = {0x01, 0xAB, 0xFF};
  EXPECT_EQ(toString(makeFrame(0x123, bytes, 3)), "123#01ABFF");
  EXPECT_EQ(toString(makeFrame(0x7, bytes, 0)), "007#");
  CanFrame f = makeFrame(0x1ABCDEF, bytes, 1);
  f.id |= kEffFlag;
  EXPECT_EQ(toString(f), "01ABCDEF#01");
  f = makeFrame(0x123, bytes, 0);
  f.id |= kRtrFlag;
  EXPECT_EQ(toString(f), "123#R");
  f.id = kErrFlag | 0x40;
  f.dlc = 8;
  EXPECT_EQ(toString(f).rfind("ERR#00000040:", 0), 0u);
  f = makeFrame(0x1, bytes, 0);
  f.dlc = 12;  // malformed: shown, not trusted
  EXPECT_NE(toString(f).find("dlc 12"), std::string::npos);
}

}  // namespace
}  // namespace adroit::driver::can
