#include "adroit_driver/can_protocol.h"

#include <cmath>
#include <limits>

namespace adroit::driver::can {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Frame lengths (docs: "Frames").
constexpr std::uint8_t kPackedDlc = 8;  // seq + 4 x 14 bits
constexpr std::uint8_t kSupplyDlc = 3;  // seq + u16
constexpr std::uint8_t kHeartbeatDlc = 4;
constexpr std::uint8_t kEstopDlc = 3;
constexpr std::uint8_t kFaultDlc = 5;
constexpr std::uint8_t valveDlc(int count) { return static_cast<std::uint8_t>(1 + 2 * count); }

// ---- little-endian fields

void putU16(std::uint8_t* p, std::uint16_t v) {
  p[0] = static_cast<std::uint8_t>(v & 0xFF);
  p[1] = static_cast<std::uint8_t>(v >> 8);
}
std::uint16_t getU16(const std::uint8_t* p) { return static_cast<std::uint16_t>(p[0] | (p[1] << 8)); }

// Bytes 1..7 of a packed frame are one 56-bit little-endian number; field k is its bits
// 14k .. 14k+13. Four fields in seven bytes leave room for the sequence byte: with 16-bit
// fields a 24-joint sample would need 8 frames instead of 6 (docs: "Bus load").
void packFields(const std::array<std::uint16_t, kPackedFields>& raw, std::uint8_t* bytes) {
  std::uint64_t bits = 0;
  for (int k = 0; k < kPackedFields; ++k) bits |= static_cast<std::uint64_t>(raw[k] & 0x3FFF) << (14 * k);
  for (int b = 0; b < 7; ++b) bytes[b] = static_cast<std::uint8_t>(bits >> (8 * b));
}
std::array<std::uint16_t, kPackedFields> unpackFields(const std::uint8_t* bytes) {
  std::uint64_t bits = 0;
  for (int b = 0; b < 7; ++b) bits |= static_cast<std::uint64_t>(bytes[b]) << (8 * b);
  std::array<std::uint16_t, kPackedFields> raw{};
  for (int k = 0; k < kPackedFields; ++k) raw[k] = static_cast<std::uint16_t>((bits >> (14 * k)) & 0x3FFF);
  return raw;
}
std::int32_t signExtend14(std::uint16_t field) {
  return (field & 0x2000) ? static_cast<std::int32_t>(field) - 0x4000 : static_cast<std::int32_t>(field);
}

// Rounds a value already in LSB units to the nearest raw value in [lo, hi], flagging clamps.
std::int32_t toRaw(double lsbs, std::int32_t lo, std::int32_t hi, bool* clamped) {
  const double r = std::nearbyint(lsbs);  // +-inf stay infinite and clamp below
  if (r > hi) { *clamped = true; return hi; }
  if (r < lo) { *clamped = true; return lo; }
  return static_cast<std::int32_t>(r);
}

// One 14-bit unsigned quantity: value = raw * unit / per (integers, so that decoding is one
// correctly rounded division and re-encoding gives the raw value back); NaN = no reading.
struct UnsignedScale {
  double unit;
  double per;
  std::int32_t max_raw;
};
constexpr UnsignedScale kTouchScale{1.0, kTouchPerLsb, kTouchMaxRaw};            // 1 mN
constexpr UnsignedScale kPressureScale{kPressureLsb, 1.0, kPressureMaxRaw};      // 100 Pa
constexpr UnsignedScale kLengthScale{1.0, kLengthPerLsb, kLengthMaxRaw};         // 10 um

std::uint16_t encodeUnsigned(double value, const UnsignedScale& s, bool* clamped) {
  if (std::isnan(value)) return kUnsignedNoReading;
  return static_cast<std::uint16_t>(toRaw(value * s.per / s.unit, 0, s.max_raw, clamped));
}
// False when the raw value is neither in range nor "no reading".
bool decodeUnsigned(std::uint16_t raw, const UnsignedScale& s, double* value) {
  if (raw == kUnsignedNoReading) {
    *value = kNaN;
    return true;
  }
  if (raw > s.max_raw) return false;
  *value = raw * s.unit / s.per;
  return true;
}

std::uint16_t encodeAngle(double rad, bool* clamped) {
  if (std::isnan(rad)) return static_cast<std::uint16_t>(kJointNoReading & 0x3FFF);
  return static_cast<std::uint16_t>(toRaw(rad / kJointAngleLsb, -kJointAngleMaxRaw, kJointAngleMaxRaw, clamped) & 0x3FFF);
}
bool decodeAngle(std::uint16_t field, double* rad) {
  const std::int32_t raw = signExtend14(field);
  if (raw == kJointNoReading) { *rad = kNaN; return true; }
  if (raw > kJointAngleMaxRaw || raw < -kJointAngleMaxRaw) return false;
  *rad = raw * kJointAngleLsb;  // power of two: exact
  return true;
}

// Address checks shared by the packed frames: first index a multiple of 4 below 32.
bool packedIndexOk(int first) { return first >= 0 && first < kMaxJoints && first % kPackedFields == 0; }

// Checks common to every typed decoder: a standard data frame of the expected type.
DecodeError checkType(const CanFrame& f, FrameType expected, FrameType alt = FrameType::kUnknown) {
  if (!isStandardData(f)) return DecodeError::kNotDataFrame;
  const FrameType t = frameType(f.id);
  if (t == FrameType::kUnknown) return DecodeError::kUnknownId;
  if (t != expected && t != alt) return DecodeError::kWrongType;
  return DecodeError::kNone;
}

CanFrame blankFrame(std::uint32_t id, std::uint8_t dlc) {
  CanFrame f;
  f.id = id;
  f.dlc = dlc;
  return f;
}

// Shared by joints, touch and the two sensor quantities: 4 fields after the sequence byte.
template <class Field>
EncodeResult encodePacked(std::uint32_t id, std::uint8_t seq, const std::array<double, kPackedFields>& values,
                          Field field, CanFrame* out) {
  EncodeResult result;
  std::array<std::uint16_t, kPackedFields> raw{};
  for (int k = 0; k < kPackedFields; ++k) {
    bool clamped = false;
    raw[k] = field(values[k], &clamped);
    if (clamped) result.clamped |= static_cast<std::uint8_t>(1u << k);
  }
  CanFrame f = blankFrame(id, kPackedDlc);
  f.data[0] = seq;
  packFields(raw, f.data + 1);
  *out = f;
  return result;
}

template <class Field>
DecodeError decodePacked(const CanFrame& f, Field field, std::array<double, kPackedFields>* values) {
  if (f.dlc != kPackedDlc) return DecodeError::kBadDlc;
  const auto raw = unpackFields(f.data + 1);
  std::array<double, kPackedFields> v{};
  for (int k = 0; k < kPackedFields; ++k) {
    if (!field(raw[k], &v[k])) return DecodeError::kRawOutOfRange;
  }
  *values = v;
  return DecodeError::kNone;
}

}  // namespace

bool isKnownNode(std::uint8_t node) {
  return node == kHostNode || node == kPalmNode ||
         (node >= kValveBoardNodeBase && node < kValveBoardNodeBase + kMaxBoards) ||
         (node >= kSensorBoardNodeBase && node < kSensorBoardNodeBase + kMaxBoards);
}

FrameType frameType(std::uint32_t id) {
  if (id > kSffMask) return FrameType::kUnknown;
  const auto in = [id](std::uint32_t base, std::uint32_t count) { return id >= base && id < base + count; };
  const auto node = [id](std::uint32_t base) { return static_cast<std::uint8_t>(id - base); };
  if (in(kEstopIdBase, 0x40)) return isKnownNode(node(kEstopIdBase)) ? FrameType::kEstop : FrameType::kUnknown;
  if (in(kFaultIdBase, 0x40)) return isKnownNode(node(kFaultIdBase)) ? FrameType::kFault : FrameType::kUnknown;
  if (in(kValveCommandIdBase, kMaxBoards * kGroupsPerBoard)) return FrameType::kValveCommand;
  if (in(kJointAnglesIdBase, kGroupsPerBoard)) return FrameType::kJointAngles;
  if (in(kTouchIdBase, kGroupsPerBoard)) return FrameType::kTouch;
  if (in(kPressureIdBase, kMaxBoards * kGroupsPerBoard)) return FrameType::kPressure;
  if (in(kLengthIdBase, kMaxBoards * kGroupsPerBoard)) return FrameType::kLength;
  if (in(kSupplyIdBase, kMaxBoards)) return FrameType::kSupply;
  if (in(kHeartbeatIdBase, 0x40)) {
    return isKnownNode(node(kHeartbeatIdBase)) ? FrameType::kHeartbeat : FrameType::kUnknown;
  }
  return FrameType::kUnknown;
}

const char* frameTypeName(FrameType type) {
  switch (type) {
    case FrameType::kUnknown: return "unknown";
    case FrameType::kEstop: return "estop";
    case FrameType::kFault: return "fault";
    case FrameType::kValveCommand: return "valve_command";
    case FrameType::kJointAngles: return "joint_angles";
    case FrameType::kTouch: return "touch";
    case FrameType::kPressure: return "pressure";
    case FrameType::kLength: return "length";
    case FrameType::kSupply: return "supply";
    case FrameType::kHeartbeat: return "heartbeat";
  }
  return "?";
}

const char* decodeErrorName(DecodeError error) {
  switch (error) {
    case DecodeError::kNone: return "ok";
    case DecodeError::kNotDataFrame: return "not a standard data frame";
    case DecodeError::kUnknownId: return "unknown identifier";
    case DecodeError::kWrongType: return "wrong frame type";
    case DecodeError::kBadDlc: return "wrong length";
    case DecodeError::kReservedBits: return "reserved bits set";
    case DecodeError::kRawOutOfRange: return "raw value out of range";
    case DecodeError::kBadField: return "undefined field value";
    case DecodeError::kBadVersion: return "protocol version mismatch";
  }
  return "?";
}

const char* encodeErrorName(EncodeError error) {
  switch (error) {
    case EncodeError::kNone: return "ok";
    case EncodeError::kBadAddress: return "address out of range";
    case EncodeError::kBadCount: return "bad channel count";
    case EncodeError::kBadField: return "undefined field value";
    case EncodeError::kNotFinite: return "value not finite";
  }
  return "?";
}

// ---------------------------------------------------------------- encoders

EncodeResult encode(const JointAnglesFrame& in, CanFrame* out) {
  if (!packedIndexOk(in.first_joint)) return {EncodeError::kBadAddress, 0};
  return encodePacked(kJointAnglesIdBase + in.first_joint / kPackedFields, in.seq, in.angles, encodeAngle, out);
}

EncodeResult encode(const TouchFrame& in, CanFrame* out) {
  if (!packedIndexOk(in.first_sensor)) return {EncodeError::kBadAddress, 0};
  return encodePacked(kTouchIdBase + in.first_sensor / kPackedFields, in.seq, in.forces,
                      [](double v, bool* c) { return encodeUnsigned(v, kTouchScale, c); }, out);
}

EncodeResult encode(const SensorFrame& in, CanFrame* out) {
  if (in.board >= kMaxBoards || !packedIndexOk(in.first_channel)) return {EncodeError::kBadAddress, 0};
  const std::uint32_t offset = in.board * kGroupsPerBoard + in.first_channel / kPackedFields;
  switch (in.kind) {
    case SensorKind::kPressure:
      return encodePacked(kPressureIdBase + offset, in.seq, in.values,
                          [](double v, bool* c) { return encodeUnsigned(v, kPressureScale, c); }, out);
    case SensorKind::kLength:
      return encodePacked(kLengthIdBase + offset, in.seq, in.values,
                          [](double v, bool* c) { return encodeUnsigned(v, kLengthScale, c); }, out);
  }
  return {EncodeError::kBadField, 0};
}

EncodeResult encode(const ValveCommandFrame& in, CanFrame* out) {
  if (in.board >= kMaxBoards || in.first_channel >= kMaxValveChannels ||
      in.first_channel % kValveChannelsPerFrame != 0) {
    return {EncodeError::kBadAddress, 0};
  }
  if (in.count < 1 || in.count > kValveChannelsPerFrame) return {EncodeError::kBadCount, 0};
  // A NaN must never become a valve position; the caller decides what to send instead.
  for (int k = 0; k < in.count; ++k) {
    if (std::isnan(in.volts[k])) return {EncodeError::kNotFinite, 0};
  }
  EncodeResult result;
  CanFrame f = blankFrame(kValveCommandIdBase + in.board * kGroupsPerBoard + in.first_channel / kValveChannelsPerFrame,
                          valveDlc(in.count));
  f.data[0] = in.seq;
  for (int k = 0; k < in.count; ++k) {
    bool clamped = false;
    const std::int32_t raw = toRaw(in.volts[k] * kValveMaxRaw / kValveFullScale, -kValveMaxRaw, kValveMaxRaw, &clamped);
    if (clamped) result.clamped |= static_cast<std::uint8_t>(1u << k);
    putU16(f.data + 1 + 2 * k, static_cast<std::uint16_t>(static_cast<std::int16_t>(raw)));
  }
  *out = f;
  return result;
}

EncodeResult encode(const SupplyFrame& in, CanFrame* out) {
  if (in.board >= kMaxBoards) return {EncodeError::kBadAddress, 0};
  EncodeResult result;
  bool clamped = false;
  CanFrame f = blankFrame(kSupplyIdBase + in.board, kSupplyDlc);
  f.data[0] = in.seq;
  putU16(f.data + 1, encodeUnsigned(in.pressure, kPressureScale, &clamped));
  if (clamped) result.clamped = 1;
  *out = f;
  return result;
}

EncodeResult encode(const HeartbeatFrame& in, CanFrame* out) {
  if (!isKnownNode(in.node)) return {EncodeError::kBadAddress, 0};
  if (static_cast<std::uint8_t>(in.state) > static_cast<std::uint8_t>(NodeState::kFault) ||
      (in.flags & kHeartbeatReservedFlags) != 0) {
    return {EncodeError::kBadField, 0};
  }
  // Any version is encoded (to emulate other firmware); decoders accept only their own.
  CanFrame f = blankFrame(kHeartbeatIdBase + in.node, kHeartbeatDlc);
  f.data[0] = in.seq;
  f.data[1] = in.version;
  f.data[2] = static_cast<std::uint8_t>(in.state);
  f.data[3] = in.flags;
  *out = f;
  return {};
}

namespace {
bool estopFieldsOk(EstopAction action, EstopCause cause) {
  const auto c = static_cast<std::uint8_t>(cause);
  if (c > static_cast<std::uint8_t>(EstopCause::kFault)) return false;
  switch (action) {
    case EstopAction::kEngage: return cause != EstopCause::kNone;
    case EstopAction::kRelease: return cause == EstopCause::kNone;
  }
  return false;
}
bool faultFieldsOk(FaultCode code, std::uint8_t channel) {
  const auto c = static_cast<std::uint8_t>(code);
  return c >= static_cast<std::uint8_t>(FaultCode::kCommandTimeout) &&
         c <= static_cast<std::uint8_t>(FaultCode::kInternal) && (channel < kMaxSensorChannels || channel == kNoChannel);
}
}  // namespace

EncodeResult encode(const EstopFrame& in, CanFrame* out) {
  if (!isKnownNode(in.node)) return {EncodeError::kBadAddress, 0};
  if (!estopFieldsOk(in.action, in.cause)) return {EncodeError::kBadField, 0};
  CanFrame f = blankFrame(kEstopIdBase + in.node, kEstopDlc);
  f.data[0] = in.seq;
  f.data[1] = static_cast<std::uint8_t>(in.action);
  f.data[2] = static_cast<std::uint8_t>(in.cause);
  *out = f;
  return {};
}

EncodeResult encode(const FaultFrame& in, CanFrame* out) {
  if (!isKnownNode(in.node)) return {EncodeError::kBadAddress, 0};
  if (!faultFieldsOk(in.code, in.channel)) return {EncodeError::kBadField, 0};
  CanFrame f = blankFrame(kFaultIdBase + in.node, kFaultDlc);
  f.data[0] = in.seq;
  f.data[1] = static_cast<std::uint8_t>(in.code);
  f.data[2] = in.channel;
  putU16(f.data + 3, in.detail);
  *out = f;
  return {};
}

EncodeResult encode(const Message& in, CanFrame* out) {
  return std::visit([out](const auto& m) { return encode(m, out); }, in);
}

// ---------------------------------------------------------------- decoders

DecodeError decode(const CanFrame& f, JointAnglesFrame* out) {
  if (auto e = checkType(f, FrameType::kJointAngles); e != DecodeError::kNone) return e;
  JointAnglesFrame m;
  if (auto e = decodePacked(f, decodeAngle, &m.angles); e != DecodeError::kNone) return e;
  m.first_joint = static_cast<std::uint8_t>((f.id - kJointAnglesIdBase) * kPackedFields);
  m.seq = f.data[0];
  *out = m;
  return DecodeError::kNone;
}

DecodeError decode(const CanFrame& f, TouchFrame* out) {
  if (auto e = checkType(f, FrameType::kTouch); e != DecodeError::kNone) return e;
  TouchFrame m;
  const auto field = [](std::uint16_t raw, double* v) { return decodeUnsigned(raw, kTouchScale, v); };
  if (auto e = decodePacked(f, field, &m.forces); e != DecodeError::kNone) return e;
  m.first_sensor = static_cast<std::uint8_t>((f.id - kTouchIdBase) * kPackedFields);
  m.seq = f.data[0];
  *out = m;
  return DecodeError::kNone;
}

DecodeError decode(const CanFrame& f, SensorFrame* out) {
  if (auto e = checkType(f, FrameType::kPressure, FrameType::kLength); e != DecodeError::kNone) return e;
  SensorFrame m;
  const bool pressure = frameType(f.id) == FrameType::kPressure;
  const UnsignedScale& scale = pressure ? kPressureScale : kLengthScale;
  const auto field = [&scale](std::uint16_t raw, double* v) { return decodeUnsigned(raw, scale, v); };
  if (auto e = decodePacked(f, field, &m.values); e != DecodeError::kNone) return e;
  const std::uint32_t offset = f.id - (pressure ? kPressureIdBase : kLengthIdBase);
  m.kind = pressure ? SensorKind::kPressure : SensorKind::kLength;
  m.board = static_cast<std::uint8_t>(offset / kGroupsPerBoard);
  m.first_channel = static_cast<std::uint8_t>((offset % kGroupsPerBoard) * kPackedFields);
  m.seq = f.data[0];
  *out = m;
  return DecodeError::kNone;
}

DecodeError decode(const CanFrame& f, ValveCommandFrame* out) {
  if (auto e = checkType(f, FrameType::kValveCommand); e != DecodeError::kNone) return e;
  if (f.dlc != valveDlc(1) && f.dlc != valveDlc(2) && f.dlc != valveDlc(3)) return DecodeError::kBadDlc;
  ValveCommandFrame m;
  m.count = static_cast<std::uint8_t>((f.dlc - 1) / 2);
  for (int k = 0; k < m.count; ++k) {
    const auto raw = static_cast<std::int16_t>(getU16(f.data + 1 + 2 * k));
    if (raw < -kValveMaxRaw) return DecodeError::kRawOutOfRange;  // -32768 is reserved
    m.volts[k] = raw * kValveFullScale / kValveMaxRaw;
  }
  const std::uint32_t offset = f.id - kValveCommandIdBase;
  m.board = static_cast<std::uint8_t>(offset / kGroupsPerBoard);
  m.first_channel = static_cast<std::uint8_t>((offset % kGroupsPerBoard) * kValveChannelsPerFrame);
  m.seq = f.data[0];
  *out = m;
  return DecodeError::kNone;
}

DecodeError decode(const CanFrame& f, SupplyFrame* out) {
  if (auto e = checkType(f, FrameType::kSupply); e != DecodeError::kNone) return e;
  if (f.dlc != kSupplyDlc) return DecodeError::kBadDlc;
  const std::uint16_t raw = getU16(f.data + 1);
  if (raw & 0xC000) return DecodeError::kReservedBits;  // a 14-bit code in 16 bits
  SupplyFrame m;
  if (!decodeUnsigned(raw, kPressureScale, &m.pressure)) return DecodeError::kRawOutOfRange;
  m.board = static_cast<std::uint8_t>(f.id - kSupplyIdBase);
  m.seq = f.data[0];
  *out = m;
  return DecodeError::kNone;
}

DecodeError decode(const CanFrame& f, HeartbeatFrame* out) {
  if (auto e = checkType(f, FrameType::kHeartbeat); e != DecodeError::kNone) return e;
  // The version comes first: another version may well lay out the rest differently.
  if (f.dlc < 2) return DecodeError::kBadDlc;
  if (f.data[1] != kProtocolVersion) return DecodeError::kBadVersion;
  if (f.dlc != kHeartbeatDlc) return DecodeError::kBadDlc;
  if (f.data[3] & kHeartbeatReservedFlags) return DecodeError::kReservedBits;
  if (f.data[2] > static_cast<std::uint8_t>(NodeState::kFault)) return DecodeError::kBadField;
  HeartbeatFrame m;
  m.node = static_cast<std::uint8_t>(f.id - kHeartbeatIdBase);
  m.seq = f.data[0];
  m.version = f.data[1];
  m.state = static_cast<NodeState>(f.data[2]);
  m.flags = f.data[3];
  *out = m;
  return DecodeError::kNone;
}

DecodeError decode(const CanFrame& f, EstopFrame* out) {
  if (auto e = checkType(f, FrameType::kEstop); e != DecodeError::kNone) return e;
  if (f.dlc != kEstopDlc) return DecodeError::kBadDlc;
  const auto action = static_cast<EstopAction>(f.data[1]);
  const auto cause = static_cast<EstopCause>(f.data[2]);
  if (!estopFieldsOk(action, cause)) return DecodeError::kBadField;
  EstopFrame m;
  m.node = static_cast<std::uint8_t>(f.id - kEstopIdBase);
  m.seq = f.data[0];
  m.action = action;
  m.cause = cause;
  *out = m;
  return DecodeError::kNone;
}

DecodeError decode(const CanFrame& f, FaultFrame* out) {
  if (auto e = checkType(f, FrameType::kFault); e != DecodeError::kNone) return e;
  if (f.dlc != kFaultDlc) return DecodeError::kBadDlc;
  const auto code = static_cast<FaultCode>(f.data[1]);
  if (!faultFieldsOk(code, f.data[2])) return DecodeError::kBadField;
  FaultFrame m;
  m.node = static_cast<std::uint8_t>(f.id - kFaultIdBase);
  m.seq = f.data[0];
  m.code = code;
  m.channel = f.data[2];
  m.detail = getU16(f.data + 3);
  *out = m;
  return DecodeError::kNone;
}

namespace {
template <class T>
DecodeError decodeInto(const CanFrame& f, Message* out) {
  T m;
  const DecodeError e = decode(f, &m);
  if (e == DecodeError::kNone) *out = m;
  return e;
}
}  // namespace

DecodeError decode(const CanFrame& f, Message* out) {
  if (!isStandardData(f)) return DecodeError::kNotDataFrame;
  switch (frameType(f.id)) {
    case FrameType::kUnknown: return DecodeError::kUnknownId;
    case FrameType::kEstop: return decodeInto<EstopFrame>(f, out);
    case FrameType::kFault: return decodeInto<FaultFrame>(f, out);
    case FrameType::kValveCommand: return decodeInto<ValveCommandFrame>(f, out);
    case FrameType::kJointAngles: return decodeInto<JointAnglesFrame>(f, out);
    case FrameType::kTouch: return decodeInto<TouchFrame>(f, out);
    case FrameType::kPressure:
    case FrameType::kLength: return decodeInto<SensorFrame>(f, out);
    case FrameType::kSupply: return decodeInto<SupplyFrame>(f, out);
    case FrameType::kHeartbeat: return decodeInto<HeartbeatFrame>(f, out);
  }
  return DecodeError::kUnknownId;
}

// ---------------------------------------------------------------- sequence tracking

SequenceVerdict SequenceTracker::observe(std::uint8_t seq) {
  ++stats_.frames;
  if (!started_) {
    started_ = true;
    restart(seq);
    return SequenceVerdict::kFirst;
  }
  const auto ahead = static_cast<std::uint8_t>(seq - last_);  // modulo 256
  if (ahead == 0) {
    ++stats_.duplicates;
    return SequenceVerdict::kDuplicate;
  }
  if (ahead < 128) {  // forward: the numbers skipped are lost unless they turn up late
    stats_.lost += ahead - 1u;
    seen_ = ahead >= kWindow ? 1 : (seen_ << ahead) | 1;
    span_ = span_ + ahead >= kWindow ? kWindow : span_ + ahead;
    last_ = seq;
    return ahead == 1 ? SequenceVerdict::kInOrder : SequenceVerdict::kGap;
  }
  const int behind = 256 - ahead;  // 1..128
  if (behind < span_) {  // a number after the start of counting: seen already, or lost so far
    const std::uint64_t bit = std::uint64_t{1} << behind;
    if (seen_ & bit) {
      ++stats_.duplicates;
      return SequenceVerdict::kDuplicate;
    }
    seen_ |= bit;
    --stats_.lost;  // counted when it was skipped: it has arrived after all
    ++stats_.reordered;
    return SequenceVerdict::kLate;
  }
  if (behind < kWindow) {  // from just before counting started: late, never counted lost
    ++stats_.reordered;
    return SequenceVerdict::kLate;
  }
  ++stats_.resyncs;
  restart(seq);
  return SequenceVerdict::kResync;
}

void SequenceTracker::restart(std::uint8_t seq) {
  last_ = seq;
  seen_ = 1;
  span_ = 1;
}

void SequenceTracker::reset() { *this = SequenceTracker(); }

const char* nodeStateName(NodeState state) {
  switch (state) {
    case NodeState::kBoot: return "boot";
    case NodeState::kOperational: return "operational";
    case NodeState::kSafe: return "safe";
    case NodeState::kFault: return "fault";
  }
  return "?";
}

}  // namespace adroit::driver::can
