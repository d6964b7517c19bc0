// The ADROIT CAN protocol (docs/can_protocol.md): hand-written frames of every type,
// round trips, limits and resolution, every decode rejection, the sequence tracker.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <dirent.h>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "adroit_driver/can_protocol.h"

namespace adroit::driver::can {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

CanFrame frame(std::uint32_t id, std::vector<std::uint8_t> bytes) { return makeFrame(id, bytes.data(), bytes.size()); }

void expectBytes(const CanFrame& f, std::uint32_t id, std::vector<std::uint8_t> bytes) {
  EXPECT_EQ(f.id, id);
  ASSERT_EQ(f.dlc, bytes.size());
  for (std::size_t k = 0; k < bytes.size(); ++k) EXPECT_EQ(f.data[k], bytes[k]) << "byte " << k;
  for (std::size_t k = bytes.size(); k < kMaxDataLength; ++k) EXPECT_EQ(f.data[k], 0) << "unused byte " << k;
}

// ---------------------------------------------------------------- hand-written frames

TEST(CanProtocolBytes, JointAngles) {
  // Joints 4..7 = 1 rad, -0.5 rad, 0, no reading; 14-bit fields 0x0800, 0x3C00, 0, 0x2000.
  const CanFrame f = frame(0x101, {0x2A, 0x00, 0x08, 0x00, 0x0F, 0x00, 0x00, 0x80});
  JointAnglesFrame m;
  ASSERT_EQ(decode(f, &m), DecodeError::kNone);
  EXPECT_EQ(m.first_joint, 4);
  EXPECT_EQ(m.seq, 0x2A);
  EXPECT_EQ(m.angles[0], 1.0);
  EXPECT_EQ(m.angles[1], -0.5);
  EXPECT_EQ(m.angles[2], 0.0);
  EXPECT_TRUE(std::isnan(m.angles[3]));
  CanFrame out;
  ASSERT_TRUE(encode(JointAnglesFrame{4, {1.0, -0.5, 0.0, kNaN}, 0x2A}, &out).ok());
  expectBytes(out, 0x101, {0x2A, 0x00, 0x08, 0x00, 0x0F, 0x00, 0x00, 0x80});
}

TEST(CanProtocolBytes, Touch) {
  // Sensors 0..3 = 0.5 N, 0, 16 N, no reading: fields 500, 0, 16000, 0x3FFF.
  const std::vector<std::uint8_t> bytes = {0x07, 0xF4, 0x01, 0x00, 0x00, 0xE8, 0xFF, 0xFF};
  TouchFrame m;
  ASSERT_EQ(decode(frame(0x108, bytes), &m), DecodeError::kNone);
  EXPECT_EQ(m.first_sensor, 0);
  EXPECT_EQ(m.seq, 7);
  EXPECT_DOUBLE_EQ(m.forces[0], 0.5);
  EXPECT_EQ(m.forces[1], 0.0);
  EXPECT_EQ(m.forces[2], 16.0);
  EXPECT_TRUE(std::isnan(m.forces[3]));
  CanFrame out;
  ASSERT_TRUE(encode(TouchFrame{0, {0.5, 0.0, 16.0, kNaN}, 7}, &out).ok());
  expectBytes(out, 0x108, bytes);
}

TEST(CanProtocolBytes, ValveCommand) {
  // Board 2, channels 3..5 (group 1): +5 V, -5 V, 0 V = 0x7FFF, 0x8001, 0x0000.
  const std::vector<std::uint8_t> bytes = {0x10, 0xFF, 0x7F, 0x01, 0x80, 0x00, 0x00};
  ValveCommandFrame m;
  ASSERT_EQ(decode(frame(0x091, bytes), &m), DecodeError::kNone);
  EXPECT_EQ(m.board, 2);
  EXPECT_EQ(m.first_channel, 3);
  EXPECT_EQ(m.count, 3);
  EXPECT_EQ(m.seq, 0x10);
  EXPECT_EQ(m.volts[0], 5.0);
  EXPECT_EQ(m.volts[1], -5.0);
  EXPECT_EQ(m.volts[2], 0.0);
  CanFrame out;
  ASSERT_TRUE(encode(ValveCommandFrame{2, 3, 3, {5.0, -5.0, 0.0}, 0x10}, &out).ok());
  expectBytes(out, 0x091, bytes);
  // The last group of an 8-channel board: channels 6, 7 in a 5-byte frame.
  ASSERT_TRUE(encode(ValveCommandFrame{0, 6, 2, {-5.0, 5.0, 0.0}, 1}, &out).ok());
  expectBytes(out, 0x082, {0x01, 0x01, 0x80, 0xFF, 0x7F});
}

TEST(CanProtocolBytes, PressureAndLength) {
  // Pressure, board 1, channels 4..7: 101.3 kPa, 620 kPa, 1.2 MPa, no reading.
  const std::vector<std::uint8_t> p = {0x03, 0xF5, 0x03, 0x0E, 0x06, 0xEE, 0xFE, 0xFF};
  SensorFrame m;
  ASSERT_EQ(decode(frame(0x149, p), &m), DecodeError::kNone);
  EXPECT_EQ(m.kind, SensorKind::kPressure);
  EXPECT_EQ(m.board, 1);
  EXPECT_EQ(m.first_channel, 4);
  EXPECT_EQ(m.values[0], 101300.0);
  EXPECT_EQ(m.values[1], 620000.0);
  EXPECT_EQ(m.values[2], 1.2e6);
  EXPECT_TRUE(std::isnan(m.values[3]));
  CanFrame out;
  ASSERT_TRUE(encode(SensorFrame{1, SensorKind::kPressure, 4, {101300, 620e3, 1.2e6, kNaN}, 3}, &out).ok());
  expectBytes(out, 0x149, p);
  // Length, board 0, channels 0..3: 0, 37.5 mm, 160 mm, 100 mm.
  const std::vector<std::uint8_t> l = {0x04, 0x00, 0x80, 0xA9, 0x03, 0xE8, 0x43, 0x9C};
  ASSERT_EQ(decode(frame(0x180, l), &m), DecodeError::kNone);
  EXPECT_EQ(m.kind, SensorKind::kLength);
  EXPECT_EQ(m.board, 0);
  EXPECT_EQ(m.values[0], 0.0);
  EXPECT_DOUBLE_EQ(m.values[1], 0.0375);
  EXPECT_DOUBLE_EQ(m.values[2], 0.16);
  EXPECT_DOUBLE_EQ(m.values[3], 0.1);
  ASSERT_TRUE(encode(SensorFrame{0, SensorKind::kLength, 0, {0, 0.0375, 0.16, 0.1}, 4}, &out).ok());
  expectBytes(out, 0x180, l);
}

TEST(CanProtocolBytes, Supply) {
  SupplyFrame m;
  ASSERT_EQ(decode(frame(0x1C0, {0x05, 0x38, 0x18}), &m), DecodeError::kNone);  // 6200 x 100 Pa
  EXPECT_EQ(m.board, 0);
  EXPECT_EQ(m.pressure, 620e3);
  EXPECT_EQ(m.seq, 5);
  CanFrame out;
  ASSERT_TRUE(encode(SupplyFrame{3, 620e3, 5}, &out).ok());
  expectBytes(out, 0x1C3, {0x05, 0x38, 0x18});
  ASSERT_TRUE(encode(SupplyFrame{0, kNaN, 6}, &out).ok());
  expectBytes(out, 0x1C0, {0x06, 0xFF, 0x3F});
}

TEST(CanProtocolBytes, Heartbeat) {
  HeartbeatFrame m;
  ASSERT_EQ(decode(frame(0x701, {0x09, 0x01, 0x01, 0x01}), &m), DecodeError::kNone);
  EXPECT_EQ(m.node, kPalmNode);
  EXPECT_EQ(m.seq, 9);
  EXPECT_EQ(m.version, 1);
  EXPECT_EQ(m.state, NodeState::kOperational);
  EXPECT_EQ(m.flags, kFlagEstopInput);
  CanFrame out;
  ASSERT_TRUE(encode(HeartbeatFrame{valveBoardNode(0), 1, NodeState::kSafe, kFlagWatchdog, 200}, &out).ok());
  expectBytes(out, 0x710, {200, 0x01, 0x02, 0x02});
}

TEST(CanProtocolBytes, Estop) {
  EstopFrame m;
  ASSERT_EQ(decode(frame(0x000, {0x00, 0x01, 0x01}), &m), DecodeError::kNone);
  EXPECT_EQ(m.node, kHostNode);
  EXPECT_EQ(m.action, EstopAction::kEngage);
  EXPECT_EQ(m.cause, EstopCause::kOperator);
  CanFrame out;
  ASSERT_TRUE(encode(EstopFrame{valveBoardNode(0), EstopAction::kEngage, EstopCause::kButton, 4}, &out).ok());
  expectBytes(out, 0x010, {0x04, 0x01, 0x02});
  ASSERT_TRUE(encode(EstopFrame{kHostNode, EstopAction::kRelease, EstopCause::kNone, 5}, &out).ok());
  expectBytes(out, 0x000, {0x05, 0x02, 0x00});
}

TEST(CanProtocolBytes, Fault) {
  FaultFrame m;
  ASSERT_EQ(decode(frame(0x051, {0x03, 0x01, 0x06, 0x32, 0x00}), &m), DecodeError::kNone);
  EXPECT_EQ(m.node, valveBoardNode(1));
  EXPECT_EQ(m.code, FaultCode::kCommandTimeout);
  EXPECT_EQ(m.channel, 6);
  EXPECT_EQ(m.detail, 50);
  CanFrame out;
  ASSERT_TRUE(encode(FaultFrame{sensorBoardNode(2), FaultCode::kBusError, kNoChannel, 0x8060, 1}, &out).ok());
  expectBytes(out, 0x062, {0x01, 0x05, 0xFF, 0x60, 0x80});
}

// ---------------------------------------------------------------- identifiers

TEST(CanProtocolIds, FrameTypesByIdentifier) {
  EXPECT_EQ(frameType(0x000), FrameType::kEstop);
  EXPECT_EQ(frameType(0x027), FrameType::kEstop);
  EXPECT_EQ(frameType(0x002), FrameType::kUnknown);  // node 2 does not exist
  EXPECT_EQ(frameType(0x028), FrameType::kUnknown);  // sensor board 8 does not exist
  EXPECT_EQ(frameType(0x041), FrameType::kFault);
  EXPECT_EQ(frameType(0x080), FrameType::kValveCommand);
  EXPECT_EQ(frameType(0x0BF), FrameType::kValveCommand);
  EXPECT_EQ(frameType(0x0C0), FrameType::kUnknown);
  EXPECT_EQ(frameType(0x105), FrameType::kJointAngles);
  EXPECT_EQ(frameType(0x10F), FrameType::kTouch);
  EXPECT_EQ(frameType(0x110), FrameType::kUnknown);
  EXPECT_EQ(frameType(0x17F), FrameType::kPressure);
  EXPECT_EQ(frameType(0x180), FrameType::kLength);
  EXPECT_EQ(frameType(0x1C7), FrameType::kSupply);
  EXPECT_EQ(frameType(0x1C8), FrameType::kUnknown);
  EXPECT_EQ(frameType(0x700), FrameType::kHeartbeat);
  EXPECT_EQ(frameType(0x730), FrameType::kUnknown);
  EXPECT_EQ(frameType(0x7FF), FrameType::kUnknown);
  EXPECT_EQ(frameType(0x800), FrameType::kUnknown);
  // Priorities: e-stop < fault < valve command < joints < touch < sensors < heartbeat.
  EXPECT_LT(kEstopIdBase + 0x27, kFaultIdBase);
  EXPECT_LT(kFaultIdBase + 0x27, kValveCommandIdBase);
  EXPECT_LT(kValveCommandIdBase + 63, kJointAnglesIdBase);
  EXPECT_LT(kSupplyIdBase + 7, kHeartbeatIdBase);
  for (int t = 0; t <= static_cast<int>(FrameType::kHeartbeat); ++t) {
    EXPECT_STRNE(frameTypeName(static_cast<FrameType>(t)), "?");
  }
}

// ---------------------------------------------------------------- limits, clamping, resolution

TEST(CanProtocolLimits, JointAnglesClampBeyondPiAndKeepResolution) {
  CanFrame f;
  JointAnglesFrame m;
  // +-pi are inside the range: not clamped.
  EncodeResult r = encode(JointAnglesFrame{0, {M_PI, -M_PI, 0.0, 0.0}, 0}, &f);
  EXPECT_TRUE(r.ok());
  EXPECT_EQ(r.clamped, 0);
  ASSERT_EQ(decode(f, &m), DecodeError::kNone);
  EXPECT_NEAR(m.angles[0], M_PI, kJointAngleLsb / 2);
  EXPECT_NEAR(m.angles[1], -M_PI, kJointAngleLsb / 2);
  // Beyond: clamped to the largest raw value and reported per field.
  r = encode(JointAnglesFrame{28, {0.0, 3.2, -kInf, kInf}, 0}, &f);
  EXPECT_TRUE(r.ok());
  EXPECT_EQ(r.clamped, 0b1110);
  ASSERT_EQ(decode(f, &m), DecodeError::kNone);
  EXPECT_EQ(m.first_joint, 28);
  EXPECT_EQ(m.angles[1], kJointAngleMaxRaw * kJointAngleLsb);
  EXPECT_EQ(m.angles[2], -kJointAngleMaxRaw * kJointAngleLsb);
  // Resolution: every value comes back within half an LSB.
  for (double a = -3.1; a < 3.1; a += 0.0137) {
    ASSERT_TRUE(encode(JointAnglesFrame{8, {a, -a, a / 2, 0}, 1}, &f).ok());
    ASSERT_EQ(decode(f, &m), DecodeError::kNone);
    EXPECT_LE(std::abs(m.angles[0] - a), kJointAngleLsb / 2);
    EXPECT_LE(std::abs(m.angles[1] + a), kJointAngleLsb / 2);
  }
}

TEST(CanProtocolLimits, UnsignedQuantitiesClampAtZeroAndTheirMaximum) {
  CanFrame f;
  SensorFrame s;
  EncodeResult r = encode(SensorFrame{7, SensorKind::kPressure, 28, {-100.0, 1.2e6, 1.2e6 + 100, 149.0}, 0}, &f);
  EXPECT_EQ(r.clamped, 0b0101);
  ASSERT_EQ(decode(f, &s), DecodeError::kNone);
  EXPECT_EQ(s.values[0], 0.0);
  EXPECT_EQ(s.values[1], 1.2e6);
  EXPECT_EQ(s.values[2], 1.2e6);
  EXPECT_EQ(s.values[3], 100.0);  // to the nearest 100 Pa
  r = encode(SensorFrame{0, SensorKind::kLength, 0, {0.16, 0.16 + 1e-5, 4e-6, 6e-6}, 0}, &f);
  EXPECT_EQ(r.clamped, 0b0010);
  ASSERT_EQ(decode(f, &s), DecodeError::kNone);
  EXPECT_DOUBLE_EQ(s.values[1], 0.16);
  EXPECT_EQ(s.values[2], 0.0);
  EXPECT_DOUBLE_EQ(s.values[3], 1e-5);
  TouchFrame t;
  r = encode(TouchFrame{4, {16.0, 16.001, -0.002, 0.0004}, 0}, &f);
  EXPECT_EQ(r.clamped, 0b0110);
  ASSERT_EQ(decode(f, &t), DecodeError::kNone);
  EXPECT_EQ(t.forces[1], 16.0);
  EXPECT_EQ(t.forces[3], 0.0);  // below half a millinewton
  SupplyFrame p;
  r = encode(SupplyFrame{0, 5e6, 0}, &f);
  EXPECT_EQ(r.clamped, 1);
  ASSERT_EQ(decode(f, &p), DecodeError::kNone);
  EXPECT_EQ(p.pressure, 1.2e6);
}

TEST(CanProtocolLimits, ValveCommandsClampBeyondFiveVoltsAndRefuseNaN) {
  CanFrame f;
  ValveCommandFrame v;
  EncodeResult r = encode(ValveCommandFrame{7, 21, 3, {5.0, 5.0001, -kInf}, 0}, &f);
  EXPECT_TRUE(r.ok());
  EXPECT_EQ(r.clamped, 0b110);
  ASSERT_EQ(decode(f, &v), DecodeError::kNone);
  EXPECT_EQ(f.id, 0x0BFu);
  EXPECT_EQ(v.volts[1], 5.0);
  EXPECT_EQ(v.volts[2], -5.0);
  // NaN is refused (and the output left alone): it must never become a valve position.
  CanFrame untouched = f;
  r = encode(ValveCommandFrame{0, 0, 2, {0.0, kNaN, 0.0}, 0}, &f);
  EXPECT_EQ(r.error, EncodeError::kNotFinite);
  EXPECT_TRUE(sameFrame(f, untouched));
  // Only the first `count` values matter: a NaN after them is not sent.
  EXPECT_TRUE(encode(ValveCommandFrame{0, 0, 1, {1.0, kNaN, kNaN}, 0}, &f).ok());
  // Resolution 5 / 32767 V.
  const double lsb = kValveFullScale / kValveMaxRaw;
  for (double u = -5.0; u <= 5.0; u += 0.0173) {
    ASSERT_TRUE(encode(ValveCommandFrame{1, 0, 1, {u, 0, 0}, 0}, &f).ok());
    ASSERT_EQ(decode(f, &v), DecodeError::kNone);
    EXPECT_LE(std::abs(v.volts[0] - u), lsb / 2 + 1e-15);
  }
}

TEST(CanProtocolLimits, EncodersRefuseBadAddressesAndFields) {
  CanFrame f;
  EXPECT_EQ(encode(JointAnglesFrame{3, {}, 0}, &f).error, EncodeError::kBadAddress);
  EXPECT_EQ(encode(JointAnglesFrame{32, {}, 0}, &f).error, EncodeError::kBadAddress);
  EXPECT_EQ(encode(TouchFrame{33, {}, 0}, &f).error, EncodeError::kBadAddress);
  EXPECT_EQ(encode(SensorFrame{8, SensorKind::kLength, 0, {}, 0}, &f).error, EncodeError::kBadAddress);
  EXPECT_EQ(encode(SensorFrame{0, SensorKind::kLength, 2, {}, 0}, &f).error, EncodeError::kBadAddress);
  EXPECT_EQ(encode(SensorFrame{0, static_cast<SensorKind>(9), 0, {}, 0}, &f).error, EncodeError::kBadField);
  EXPECT_EQ(encode(ValveCommandFrame{8, 0, 1, {}, 0}, &f).error, EncodeError::kBadAddress);
  EXPECT_EQ(encode(ValveCommandFrame{0, 4, 1, {}, 0}, &f).error, EncodeError::kBadAddress);
  EXPECT_EQ(encode(ValveCommandFrame{0, 24, 1, {}, 0}, &f).error, EncodeError::kBadAddress);
  EXPECT_EQ(encode(ValveCommandFrame{0, 0, 0, {}, 0}, &f).error, EncodeError::kBadCount);
  EXPECT_EQ(encode(ValveCommandFrame{0, 0, 4, {}, 0}, &f).error, EncodeError::kBadCount);
  EXPECT_EQ(encode(SupplyFrame{8, 0, 0}, &f).error, EncodeError::kBadAddress);
  EXPECT_EQ(encode(HeartbeatFrame{0x05, 1, NodeState::kBoot, 0, 0}, &f).error, EncodeError::kBadAddress);
  EXPECT_EQ(encode(HeartbeatFrame{0, 1, static_cast<NodeState>(4), 0, 0}, &f).error, EncodeError::kBadField);
  EXPECT_EQ(encode(HeartbeatFrame{0, 1, NodeState::kBoot, 0x08, 0}, &f).error, EncodeError::kBadField);
  EXPECT_EQ(encode(EstopFrame{0x30, EstopAction::kEngage, EstopCause::kButton, 0}, &f).error, EncodeError::kBadAddress);
  EXPECT_EQ(encode(EstopFrame{0, EstopAction::kEngage, EstopCause::kNone, 0}, &f).error, EncodeError::kBadField);
  EXPECT_EQ(encode(EstopFrame{0, EstopAction::kRelease, EstopCause::kButton, 0}, &f).error, EncodeError::kBadField);
  EXPECT_EQ(encode(EstopFrame{0, static_cast<EstopAction>(3), EstopCause::kButton, 0}, &f).error, EncodeError::kBadField);
  EXPECT_EQ(encode(FaultFrame{0, static_cast<FaultCode>(0), kNoChannel, 0, 0}, &f).error, EncodeError::kBadField);
  EXPECT_EQ(encode(FaultFrame{0, FaultCode::kSensor, 32, 0, 0}, &f).error, EncodeError::kBadField);
  for (int e = 0; e <= static_cast<int>(EncodeError::kNotFinite); ++e) {
    EXPECT_STRNE(encodeErrorName(static_cast<EncodeError>(e)), "?");
  }
}

// ---------------------------------------------------------------- round trips of every type

TEST(CanProtocolRoundTrip, EveryTypeThroughTheGenericCodec) {
  const Message messages[] = {
      JointAnglesFrame{20, {0.25, -1.5, kNaN, 3.0}, 255},
      TouchFrame{12, {0.0, 1.234, kNaN, 15.999}, 17},
      ValveCommandFrame{5, 12, 1, {-0.75, 0, 0}, 33},
      SensorFrame{6, SensorKind::kPressure, 8, {101325, 450000, 700000, kNaN}, 44},
      SensorFrame{2, SensorKind::kLength, 12, {0.0, 0.01234, 0.0375, 0.1}, 45},
      SupplyFrame{1, 655000, 46},
      HeartbeatFrame{sensorBoardNode(7), kProtocolVersion, NodeState::kFault, kFlagEstopInput | kFlagSupplyOpen, 47},
      EstopFrame{kPalmNode, EstopAction::kEngage, EstopCause::kFault, 48},
      FaultFrame{kHostNode, FaultCode::kVersionMismatch, kNoChannel, 2, 49},
  };
  for (const Message& in : messages) {
    CanFrame f;
    ASSERT_TRUE(encode(in, &f).ok()) << in.index();
    Message out;
    ASSERT_EQ(decode(f, &out), DecodeError::kNone) << toString(f);
    ASSERT_EQ(out.index(), in.index());
    CanFrame again;
    ASSERT_TRUE(encode(out, &again).ok());
    EXPECT_TRUE(sameFrame(f, again)) << toString(f) << " vs " << toString(again);
  }
  // Decoded values are the encoded ones to the resolution.
  CanFrame f;
  ASSERT_TRUE(encode(messages[1], &f).ok());
  TouchFrame t;
  ASSERT_EQ(decode(f, &t), DecodeError::kNone);
  EXPECT_DOUBLE_EQ(t.forces[1], 1.234);
  EXPECT_DOUBLE_EQ(t.forces[3], 15.999);
}

// Any frame a decoder accepts re-encodes to exactly the same bytes: decoding loses nothing
// and accepts only what an encoder could have produced. Random payloads of every length on
// every assigned identifier.
TEST(CanProtocolRoundTrip, AcceptedFramesReencodeExactly) {
  std::mt19937 rng(7);
  std::size_t accepted = 0;
  for (std::uint32_t id = 0; id <= kSffMask; ++id) {
    if (frameType(id) == FrameType::kUnknown) continue;
    for (int trial = 0; trial < 200; ++trial) {
      CanFrame f;
      f.id = id;
      f.dlc = static_cast<std::uint8_t>(rng() % 9);
      for (auto& b : f.data) b = static_cast<std::uint8_t>(rng());
      if (trial % 4 == 0) f.data[1] = kProtocolVersion;  // reach the heartbeat's later checks
      Message m;
      if (decode(f, &m) != DecodeError::kNone) continue;
      ++accepted;
      CanFrame again;
      ASSERT_TRUE(encode(m, &again).ok()) << toString(f);
      ASSERT_TRUE(sameFrame(f, again)) << toString(f) << " -> " << toString(again);
    }
  }
  EXPECT_GT(accepted, 3000u);  // enough of every type pass (the right length is 1 in 9)
}

// ---------------------------------------------------------------- decode rejections

TEST(CanProtocolRejects, NotAStandardDataFrame) {
  CanFrame f = frame(0x101, {0, 0, 0, 0, 0, 0, 0, 0});
  Message m;
  ASSERT_EQ(decode(f, &m), DecodeError::kNone);
  CanFrame e = f;
  e.id |= kEffFlag;
  EXPECT_EQ(decode(e, &m), DecodeError::kNotDataFrame);
  e = f;
  e.id |= kRtrFlag;
  EXPECT_EQ(decode(e, &m), DecodeError::kNotDataFrame);
  e = f;
  e.id |= kErrFlag;
  JointAnglesFrame j;
  EXPECT_EQ(decode(e, &j), DecodeError::kNotDataFrame);
}

TEST(CanProtocolRejects, UnknownIdentifiersAndWrongTypes) {
  Message m;
  for (std::uint32_t id : {0x002u, 0x03Fu, 0x0C0u, 0x0FFu, 0x110u, 0x13Fu, 0x1C8u, 0x6FFu, 0x705u, 0x7FFu}) {
    EXPECT_EQ(decode(frame(id, {0, 0, 0}), &m), DecodeError::kUnknownId) << std::hex << id;
  }
  const CanFrame joints = frame(0x100, {0, 0, 0, 0, 0, 0, 0, 0});
  ValveCommandFrame v;
  TouchFrame t;
  SensorFrame s;
  SupplyFrame p;
  HeartbeatFrame h;
  EstopFrame e;
  FaultFrame x;
  EXPECT_EQ(decode(joints, &v), DecodeError::kWrongType);
  EXPECT_EQ(decode(joints, &t), DecodeError::kWrongType);
  EXPECT_EQ(decode(joints, &s), DecodeError::kWrongType);
  EXPECT_EQ(decode(joints, &p), DecodeError::kWrongType);
  EXPECT_EQ(decode(joints, &h), DecodeError::kWrongType);
  EXPECT_EQ(decode(joints, &e), DecodeError::kWrongType);
  EXPECT_EQ(decode(joints, &x), DecodeError::kWrongType);
  JointAnglesFrame j;
  EXPECT_EQ(decode(frame(0x080, {0, 0, 0}), &j), DecodeError::kWrongType);
  EXPECT_EQ(decode(frame(0x7FF, {0, 0, 0}), &j), DecodeError::kUnknownId);
}

TEST(CanProtocolRejects, WrongLengthOfEveryType) {
  Message m;
  const std::vector<std::uint8_t> eight(8, 0);
  auto withLength = [](std::uint32_t id, std::vector<std::uint8_t> bytes, std::size_t n) {
    bytes.resize(n, 0);
    return makeFrame(id, bytes.data(), n);
  };
  struct Case {
    std::uint32_t id;
    std::vector<std::size_t> good;
  };
  const Case cases[] = {{0x100, {8}}, {0x108, {8}}, {0x140, {8}}, {0x180, {8}}, {0x080, {3, 5, 7}},
                        {0x1C0, {3}}, {0x000, {3}}, {0x040, {5}}};
  for (const Case& c : cases) {
    // Fields that make the frame valid whenever its length is right.
    std::vector<std::uint8_t> bytes = c.id == 0x000 ? std::vector<std::uint8_t>{0, 1, 1}
                                      : c.id == 0x040 ? std::vector<std::uint8_t>{0, 1, 0, 0, 0}
                                                      : eight;
    for (std::size_t n = 0; n <= 8; ++n) {
      const bool good = std::find(c.good.begin(), c.good.end(), n) != c.good.end();
      const DecodeError e = decode(withLength(c.id, bytes, n), &m);
      EXPECT_EQ(e, good ? DecodeError::kNone : DecodeError::kBadDlc) << std::hex << c.id << " dlc " << n;
    }
  }
  // Heartbeat: the version is checked as soon as it is present, then the length.
  EXPECT_EQ(decode(frame(0x700, {0}), &m), DecodeError::kBadDlc);
  EXPECT_EQ(decode(frame(0x700, {0, 1, 0}), &m), DecodeError::kBadDlc);
  EXPECT_EQ(decode(frame(0x700, {0, 1, 0, 0, 0}), &m), DecodeError::kBadDlc);
  EXPECT_EQ(decode(frame(0x700, {0, 1, 0, 0}), &m), DecodeError::kNone);
  CanFrame f = frame(0x101, eight);
  f.dlc = 9;  // impossible on a bus
  EXPECT_EQ(decode(f, &m), DecodeError::kBadDlc);
}

TEST(CanProtocolRejects, ReservedBits) {
  Message m;
  EXPECT_EQ(decode(frame(0x700, {0, 1, 1, 0x08}), &m), DecodeError::kReservedBits);
  EXPECT_EQ(decode(frame(0x700, {0, 1, 1, 0x80}), &m), DecodeError::kReservedBits);
  EXPECT_EQ(decode(frame(0x1C0, {0, 0x00, 0x40}), &m), DecodeError::kReservedBits);  // bit 14 of the code
  EXPECT_EQ(decode(frame(0x1C0, {0, 0x00, 0x80}), &m), DecodeError::kReservedBits);
}

TEST(CanProtocolRejects, RawValuesOutOfRange) {
  Message m;
  auto packed = [](std::uint32_t id, std::uint16_t f0) {
    CanFrame f;
    f.id = id;
    f.dlc = 8;
    f.data[1] = static_cast<std::uint8_t>(f0 & 0xFF);  // field 0 = low 14 bits of bytes 1, 2
    f.data[2] = static_cast<std::uint8_t>(f0 >> 8);
    return f;
  };
  // Joint angles: +-6434 valid, -8192 = no reading, anything else beyond +-6434 invalid.
  EXPECT_EQ(decode(packed(0x100, 6434), &m), DecodeError::kNone);
  EXPECT_EQ(decode(packed(0x100, 6435), &m), DecodeError::kRawOutOfRange);
  EXPECT_EQ(decode(packed(0x100, 0x3FFF & -6434), &m), DecodeError::kNone);
  EXPECT_EQ(decode(packed(0x100, 0x3FFF & -6435), &m), DecodeError::kRawOutOfRange);
  EXPECT_EQ(decode(packed(0x100, 0x2000), &m), DecodeError::kNone);  // no reading
  EXPECT_EQ(decode(packed(0x100, 0x2001), &m), DecodeError::kRawOutOfRange);
  // Unsigned quantities: up to their maximum, or 0x3FFF (no reading).
  const std::pair<std::uint32_t, std::uint16_t> unsigned_cases[] = {
      {0x108, kTouchMaxRaw}, {0x140, kPressureMaxRaw}, {0x180, kLengthMaxRaw}};
  for (const auto& [id, max] : unsigned_cases) {
    EXPECT_EQ(decode(packed(id, max), &m), DecodeError::kNone) << std::hex << id;
    EXPECT_EQ(decode(packed(id, max + 1), &m), DecodeError::kRawOutOfRange) << std::hex << id;
    EXPECT_EQ(decode(packed(id, 0x3FFE), &m), DecodeError::kRawOutOfRange) << std::hex << id;
    EXPECT_EQ(decode(packed(id, 0x3FFF), &m), DecodeError::kNone) << std::hex << id;
  }
  // A bad field anywhere rejects the frame: field 3 = bits 42..55 = bytes 6, 7.
  CanFrame f = packed(0x140, 0);
  f.data[6] = 0xFC;  // field 3 = 0x3FFF: no reading, fine
  f.data[7] = 0xFF;
  EXPECT_EQ(decode(f, &m), DecodeError::kNone);
  f.data[6] = 0xF8;  // 0x3FFE
  EXPECT_EQ(decode(f, &m), DecodeError::kRawOutOfRange);
  EXPECT_EQ(decode(frame(0x1C0, {0, 0xE1, 0x2E}), &m), DecodeError::kRawOutOfRange);  // 12001
  // Valve commands: -32768 is reserved.
  EXPECT_EQ(decode(frame(0x080, {0, 0x01, 0x80}), &m), DecodeError::kNone);  // -32767
  EXPECT_EQ(decode(frame(0x080, {0, 0x00, 0x80}), &m), DecodeError::kRawOutOfRange);
  EXPECT_EQ(decode(frame(0x080, {0, 0, 0, 0, 0, 0x00, 0x80}), &m), DecodeError::kRawOutOfRange);
}

TEST(CanProtocolRejects, UndefinedFieldValues) {
  Message m;
  EXPECT_EQ(decode(frame(0x700, {0, 1, 4, 0}), &m), DecodeError::kBadField);  // state
  EXPECT_EQ(decode(frame(0x000, {0, 0, 1}), &m), DecodeError::kBadField);     // action 0
  EXPECT_EQ(decode(frame(0x000, {0, 3, 1}), &m), DecodeError::kBadField);     // action 3
  EXPECT_EQ(decode(frame(0x000, {0, 1, 0}), &m), DecodeError::kBadField);     // engage without cause
  EXPECT_EQ(decode(frame(0x000, {0, 1, 5}), &m), DecodeError::kBadField);     // cause 5
  EXPECT_EQ(decode(frame(0x000, {0, 2, 1}), &m), DecodeError::kBadField);     // release with a cause
  EXPECT_EQ(decode(frame(0x040, {0, 0, 0xFF, 0, 0}), &m), DecodeError::kBadField);  // code 0
  EXPECT_EQ(decode(frame(0x040, {0, 9, 0xFF, 0, 0}), &m), DecodeError::kBadField);  // code 9
  EXPECT_EQ(decode(frame(0x040, {0, 2, 32, 0, 0}), &m), DecodeError::kBadField);    // channel 32
  EXPECT_EQ(decode(frame(0x040, {0, 2, 31, 0, 0}), &m), DecodeError::kNone);
}

TEST(CanProtocolRejects, OtherProtocolVersions) {
  Message m;
  EXPECT_EQ(decode(frame(0x700, {0, 0, 1, 0}), &m), DecodeError::kBadVersion);
  EXPECT_EQ(decode(frame(0x700, {0, 2, 1, 0}), &m), DecodeError::kBadVersion);
  EXPECT_EQ(decode(frame(0x700, {0, 2, 1, 0, 0, 0, 0, 0}), &m), DecodeError::kBadVersion);  // v2 may be longer
  CanFrame f;
  ASSERT_TRUE(encode(HeartbeatFrame{kPalmNode, 7, NodeState::kOperational, 0, 0}, &f).ok());  // emulating old firmware
  EXPECT_EQ(decode(f, &m), DecodeError::kBadVersion);
  for (int e = 0; e <= static_cast<int>(DecodeError::kBadVersion); ++e) {
    EXPECT_STRNE(decodeErrorName(static_cast<DecodeError>(e)), "?");
  }
}

TEST(CanProtocolRejects, OutputIsLeftAloneOnError) {
  JointAnglesFrame j{8, {1, 2, 3, 0}, 99};
  EXPECT_EQ(decode(frame(0x100, {0, 0}), &j), DecodeError::kBadDlc);
  EXPECT_EQ(j.first_joint, 8);
  EXPECT_EQ(j.seq, 99);
  EXPECT_EQ(j.angles[1], 2.0);
  Message m = EstopFrame{};
  EXPECT_EQ(decode(frame(0x7FF, {}), &m), DecodeError::kUnknownId);
  EXPECT_TRUE(std::holds_alternative<EstopFrame>(m));
}

// ---------------------------------------------------------------- seed corpus

#ifdef ADROIT_CAN_CORPUS_DIR
TEST(CanProtocolCorpus, SeedFilesAreValidFramesOfEveryType) {
  DIR* dir = opendir(ADROIT_CAN_CORPUS_DIR);
  ASSERT_NE(dir, nullptr) << ADROIT_CAN_CORPUS_DIR;
  std::vector<bool> seen(static_cast<std::size_t>(FrameType::kHeartbeat) + 1, false);
  int files = 0;
  while (dirent* entry = readdir(dir)) {
    if (entry->d_name[0] == '.') continue;
    const std::string path = std::string(ADROIT_CAN_CORPUS_DIR) + "/" + entry->d_name;
    std::ifstream in(path, std::ios::binary);
    const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ASSERT_FALSE(bytes.empty()) << path;
    ASSERT_EQ(bytes.size() % sizeof(CanFrame), 0u) << path;
    for (std::size_t k = 0; k < bytes.size(); k += sizeof(CanFrame)) {
      CanFrame f;
      std::memcpy(&f, bytes.data() + k, sizeof f);
      Message m;
      EXPECT_EQ(decode(f, &m), DecodeError::kNone) << path << ": " << toString(f);
      seen[static_cast<std::size_t>(frameType(f.id))] = true;
    }
    ++files;
  }
  closedir(dir);
  EXPECT_GE(files, 8);
  for (std::size_t t = 1; t < seen.size(); ++t) EXPECT_TRUE(seen[t]) << frameTypeName(static_cast<FrameType>(t));
}
#endif

// ---------------------------------------------------------------- sequence tracker

TEST(SequenceTracker, CountsInOrderFramesAcrossTheWrap) {
  SequenceTracker t;
  EXPECT_EQ(t.observe(250), SequenceVerdict::kFirst);
  for (int k = 251; k < 251 + 300; ++k) ASSERT_EQ(t.observe(static_cast<std::uint8_t>(k)), SequenceVerdict::kInOrder) << k;
  EXPECT_EQ(t.stats().frames, 301u);
  EXPECT_EQ(t.stats().lost, 0u);
  EXPECT_EQ(t.stats().duplicates, 0u);
  EXPECT_EQ(t.stats().resyncs, 0u);
}

TEST(SequenceTracker, CountsLostFramesAcrossTheWrap) {
  SequenceTracker t;
  t.observe(250);
  EXPECT_EQ(t.observe(3), SequenceVerdict::kGap);  // 251..255, 0, 1, 2 missing
  EXPECT_EQ(t.stats().lost, 8u);
  EXPECT_EQ(t.observe(4), SequenceVerdict::kInOrder);
  EXPECT_EQ(t.observe(4 + 127), SequenceVerdict::kGap);  // the largest step still read as forward
  EXPECT_EQ(t.stats().lost, 8u + 126u);
  EXPECT_EQ(t.stats().resyncs, 0u);
}

TEST(SequenceTracker, DuplicatesAndLateFrames) {
  SequenceTracker t;
  t.observe(10);
  t.observe(11);
  EXPECT_EQ(t.observe(11), SequenceVerdict::kDuplicate);
  EXPECT_EQ(t.observe(14), SequenceVerdict::kGap);  // 12, 13 lost so far
  EXPECT_EQ(t.stats().lost, 2u);
  EXPECT_EQ(t.observe(12), SequenceVerdict::kLate);  // not lost after all
  EXPECT_EQ(t.stats().lost, 1u);
  EXPECT_EQ(t.stats().reordered, 1u);
  EXPECT_EQ(t.observe(12), SequenceVerdict::kDuplicate);
  EXPECT_EQ(t.observe(10), SequenceVerdict::kDuplicate);
  EXPECT_EQ(t.observe(15), SequenceVerdict::kInOrder);
  EXPECT_EQ(t.stats().duplicates, 3u);
  EXPECT_EQ(t.stats().frames, 8u);
  EXPECT_EQ(t.stats().lost, 1u);  // 13 never came
}

TEST(SequenceTracker, LateFrameAcrossTheWrap) {
  SequenceTracker t;
  t.observe(254);
  EXPECT_EQ(t.observe(1), SequenceVerdict::kGap);  // 255, 0 missing
  EXPECT_EQ(t.observe(255), SequenceVerdict::kLate);
  EXPECT_EQ(t.observe(0), SequenceVerdict::kLate);
  EXPECT_EQ(t.stats().lost, 0u);
  EXPECT_EQ(t.stats().reordered, 2u);
}

TEST(SequenceTracker, FramesFromBeforeTheStartAreLateNotLost) {
  SequenceTracker t;
  t.observe(100);
  EXPECT_EQ(t.observe(99), SequenceVerdict::kLate);
  EXPECT_EQ(t.stats().lost, 0u);  // never counted, so never uncounted
  EXPECT_EQ(t.stats().reordered, 1u);
}

TEST(SequenceTracker, AJumpBackBeyondTheWindowRestartsTheCount) {
  SequenceTracker t;
  for (int k = 0; k <= 100; ++k) t.observe(static_cast<std::uint8_t>(k));
  EXPECT_EQ(t.observe(0), SequenceVerdict::kResync);  // the sender rebooted
  EXPECT_EQ(t.observe(1), SequenceVerdict::kInOrder);
  EXPECT_EQ(t.stats().resyncs, 1u);
  EXPECT_EQ(t.stats().lost, 0u);
  // Exactly half the counter range away is read as backwards: a resync.
  EXPECT_EQ(t.observe(129), SequenceVerdict::kResync);
  t.reset();
  EXPECT_EQ(t.stats().frames, 0u);
  EXPECT_EQ(t.observe(7), SequenceVerdict::kFirst);
}

TEST(SequenceTracker, LateFramesAfterALongGapStillUncount) {
  SequenceTracker t;
  t.observe(0);
  EXPECT_EQ(t.observe(100), SequenceVerdict::kGap);  // 1..99 lost
  EXPECT_EQ(t.stats().lost, 99u);
  EXPECT_EQ(t.observe(99), SequenceVerdict::kLate);   // within the window
  EXPECT_EQ(t.observe(37), SequenceVerdict::kLate);   // 63 back: still within it
  EXPECT_EQ(t.observe(36), SequenceVerdict::kResync);  // 64 back: beyond it
  EXPECT_EQ(t.stats().lost, 97u);
}

}  // namespace
}  // namespace adroit::driver::can
