// The ADROIT CAN protocol (docs/can_protocol.md): identifiers, scaling, typed frames,
// encoders and decoders, and per-stream sequence tracking. ROS-free; encode and decode
// allocate nothing and never throw: an encoder clamps out-of-range physical values and
// says which, a decoder checks every frame strictly and returns a typed error.
#pragma once

#include <array>
#include <cstdint>
#include <variant>

#include "adroit_driver/can_frame.h"

namespace adroit::driver::can {

constexpr std::uint8_t kProtocolVersion = 1;  // carried in every heartbeat

// ---------------------------------------------------------------- nodes and identifiers
// A node number (6 bits) names the sender of e-stop, fault and heartbeat frames.
constexpr std::uint8_t kHostNode = 0x00;
constexpr std::uint8_t kPalmNode = 0x01;
constexpr std::uint8_t kValveBoardNodeBase = 0x10;   // + board, board 0..7
constexpr std::uint8_t kSensorBoardNodeBase = 0x20;  // + board, board 0..7
constexpr std::uint8_t kMaxBoards = 8;               // of each kind
constexpr std::uint8_t kGroupsPerBoard = 8;          // data frames per board and quantity
inline constexpr std::uint8_t valveBoardNode(std::uint8_t board) { return kValveBoardNodeBase + board; }
inline constexpr std::uint8_t sensorBoardNode(std::uint8_t board) { return kSensorBoardNodeBase + board; }
bool isKnownNode(std::uint8_t node);

// 11-bit identifiers; a lower identifier wins arbitration (docs: "Identifiers").
constexpr std::uint32_t kEstopIdBase = 0x000;         // + node
constexpr std::uint32_t kFaultIdBase = 0x040;         // + node
constexpr std::uint32_t kValveCommandIdBase = 0x080;  // + 8 * board + group
constexpr std::uint32_t kJointAnglesIdBase = 0x100;   // + group
constexpr std::uint32_t kTouchIdBase = 0x108;         // + group
constexpr std::uint32_t kPressureIdBase = 0x140;      // + 8 * board + group
constexpr std::uint32_t kLengthIdBase = 0x180;        // + 8 * board + group
constexpr std::uint32_t kSupplyIdBase = 0x1C0;        // + board
constexpr std::uint32_t kHeartbeatIdBase = 0x700;     // + node

// ---------------------------------------------------------------- scaling
// Packed frames carry four 14-bit fields; valve commands three 16-bit fields.
constexpr int kPackedFields = 4;
constexpr int kValveChannelsPerFrame = 3;
constexpr int kMaxJoints = kGroupsPerBoard * kPackedFields;          // 32
constexpr int kMaxTouchSensors = kGroupsPerBoard * kPackedFields;    // 32
constexpr int kMaxSensorChannels = kGroupsPerBoard * kPackedFields;  // 32 per sensor board
constexpr int kMaxValveChannels = kGroupsPerBoard * kValveChannelsPerFrame;  // 24 per valve board

constexpr double kJointAngleLsb = 1.0 / 2048;  // rad (0.49 mrad)
constexpr std::int32_t kJointAngleMaxRaw = 6434;  // +-3.1416 rad: covers [-pi, pi]
constexpr std::int32_t kJointNoReading = -8192;   // 14-bit two's complement minimum
constexpr double kTouchPerLsb = 1000.0;        // LSB per N (1 mN resolution)
constexpr std::int32_t kTouchMaxRaw = 16000;   // 16 N
constexpr double kPressureLsb = 100.0;         // Pa absolute
constexpr std::int32_t kPressureMaxRaw = 12000;  // 1.2 MPa
constexpr double kLengthPerLsb = 100000.0;     // LSB per m (10 um resolution)
constexpr std::int32_t kLengthMaxRaw = 16000;  // 0.16 m
constexpr std::int32_t kUnsignedNoReading = 0x3FFF;  // 14-bit maximum
constexpr double kValveFullScale = 5.0;        // V; raw +-32767 <-> +-5 V (0.153 mV)
constexpr std::int32_t kValveMaxRaw = 32767;   // raw -32768 is reserved

// ---------------------------------------------------------------- typed frames
// Every frame's first byte is its sender's sequence counter for that identifier (docs).
// "No reading" (a missing or failed sensor, an unused field) is NaN in the structs.

// Palm MCU -> host, 500 Hz: joints first_joint .. first_joint + 3 (protocol joint index).
struct JointAnglesFrame {
  std::uint8_t first_joint = 0;  // multiple of 4, < 32
  std::array<double, kPackedFields> angles{};  // rad
  std::uint8_t seq = 0;
};

// Palm MCU -> host, 250 Hz: touch sensors first_sensor .. first_sensor + 3.
struct TouchFrame {
  std::uint8_t first_sensor = 0;  // multiple of 4, < 32
  std::array<double, kPackedFields> forces{};  // N, >= 0
  std::uint8_t seq = 0;
};

// Host -> valve board, 200 Hz: channels first_channel .. first_channel + count - 1.
struct ValveCommandFrame {
  std::uint8_t board = 0;          // 0..7
  std::uint8_t first_channel = 0;  // multiple of 3, < 24
  std::uint8_t count = kValveChannelsPerFrame;  // 1..3 (the frame's length follows)
  std::array<double, kValveChannelsPerFrame> volts{};  // -5..5 V, 0 = centre, < 0 exhausts
  std::uint8_t seq = 0;
};

enum class SensorKind : std::uint8_t { kPressure, kLength };

// Sensor board -> host, 250 Hz: one quantity of channels first_channel .. first_channel + 3.
struct SensorFrame {
  std::uint8_t board = 0;          // 0..7
  SensorKind kind = SensorKind::kPressure;
  std::uint8_t first_channel = 0;  // multiple of 4, < 32
  std::array<double, kPackedFields> values{};  // Pa absolute, or m of piston travel
  std::uint8_t seq = 0;
};

// Sensor board -> host, 250 Hz: the supply pressure (the board wired to the supply sensor).
struct SupplyFrame {
  std::uint8_t board = 0;
  double pressure = 0;  // Pa absolute
  std::uint8_t seq = 0;
};

enum class NodeState : std::uint8_t {
  kBoot = 0,         // starting; a valve board holds its valves at exhaust
  kOperational = 1,  // streaming / applying commands
  kSafe = 2,         // valve board: every valve at -5 V, supply valve closed (thesis 3.7)
  kFault = 3,        // as kSafe, until the board is reset
};
// Heartbeat flag bits; the others are reserved (zero).
constexpr std::uint8_t kFlagEstopInput = 0x01;  // the node's hardware e-stop input is held
constexpr std::uint8_t kFlagWatchdog = 0x02;    // valve board: its command watchdog tripped
constexpr std::uint8_t kFlagSupplyOpen = 0x04;  // the board that drives the supply valve: open
constexpr std::uint8_t kHeartbeatReservedFlags = 0xF8;

const char* nodeStateName(NodeState state);  // "boot", "operational", "safe", "fault"

// Every node (host included) -> bus, 10 Hz.
struct HeartbeatFrame {
  std::uint8_t node = 0;
  std::uint8_t version = kProtocolVersion;
  NodeState state = NodeState::kBoot;
  std::uint8_t flags = 0;
  std::uint8_t seq = 0;
};

enum class EstopAction : std::uint8_t { kEngage = 1, kRelease = 2 };
enum class EstopCause : std::uint8_t {
  kNone = 0,      // only with kRelease
  kOperator = 1,  // software e-stop (service call, operator)
  kButton = 2,    // hardware e-stop input
  kWatchdog = 3,  // a command or heartbeat watchdog expired
  kFault = 4,     // a fault (bus, sensor, physics) made the sender stop everything
};

// Any node -> bus, on the event (the host repeats it on every bus).
struct EstopFrame {
  std::uint8_t node = 0;
  EstopAction action = EstopAction::kEngage;
  EstopCause cause = EstopCause::kOperator;
  std::uint8_t seq = 0;
};

enum class FaultCode : std::uint8_t {
  kCommandTimeout = 1,   // channel: first channel of the stale group; detail: ms since its last command
  kSensor = 2,           // channel; detail: the raw ADC reading
  kValveDriver = 3,      // channel; detail: 0 open load, 1 short / over-current
  kSupplyPressure = 4,   // detail: supply pressure in kPa absolute
  kBusError = 5,         // detail: tx error count << 8 | rx error count
  kVersionMismatch = 6,  // detail: the version seen
  kOverTemperature = 7,  // detail: degrees C
  kInternal = 8,         // detail: board specific
};
constexpr std::uint8_t kNoChannel = 0xFF;

// Any node -> bus, once per new fault.
struct FaultFrame {
  std::uint8_t node = 0;
  FaultCode code = FaultCode::kInternal;
  std::uint8_t channel = kNoChannel;
  std::uint16_t detail = 0;
  std::uint8_t seq = 0;
};

using Message = std::variant<EstopFrame, FaultFrame, ValveCommandFrame, JointAnglesFrame, TouchFrame,
                             SensorFrame, SupplyFrame, HeartbeatFrame>;

enum class FrameType : std::uint8_t {
  kUnknown, kEstop, kFault, kValveCommand, kJointAngles, kTouch, kPressure, kLength, kSupply, kHeartbeat
};
// From an 11-bit identifier alone (kUnknown for unassigned identifiers and unknown nodes).
FrameType frameType(std::uint32_t standard_id);
const char* frameTypeName(FrameType type);

// ---------------------------------------------------------------- encoding
enum class EncodeError : std::uint8_t {
  kNone,
  kBadAddress,  // board, node, group or first index out of range or not aligned
  kBadCount,    // valve command count not in 1..3
  kBadField,    // enum value not defined, reserved flag bits set, release with a cause
  kNotFinite,   // NaN valve command: never sent (a sensor's NaN means "no reading")
};

struct EncodeResult {
  EncodeError error = EncodeError::kNone;
  std::uint8_t clamped = 0;  // bit k: value k was out of range and was clamped
  bool ok() const { return error == EncodeError::kNone; }
};

// On success *out holds the frame (unused payload bytes zero); on error *out is untouched.
EncodeResult encode(const JointAnglesFrame& in, CanFrame* out);
EncodeResult encode(const TouchFrame& in, CanFrame* out);
EncodeResult encode(const ValveCommandFrame& in, CanFrame* out);
EncodeResult encode(const SensorFrame& in, CanFrame* out);
EncodeResult encode(const SupplyFrame& in, CanFrame* out);
EncodeResult encode(const HeartbeatFrame& in, CanFrame* out);
EncodeResult encode(const EstopFrame& in, CanFrame* out);
EncodeResult encode(const FaultFrame& in, CanFrame* out);
EncodeResult encode(const Message& in, CanFrame* out);

// ---------------------------------------------------------------- decoding
enum class DecodeError : std::uint8_t {
  kNone,
  kNotDataFrame,   // extended identifier, remote request or error frame
  kUnknownId,      // unassigned identifier or unknown node
  kWrongType,      // a typed decoder was given another frame type
  kBadDlc,         // length not the one the frame type has
  kReservedBits,   // a reserved bit is set
  kRawOutOfRange,  // a raw value outside the quantity's range (and not "no reading")
  kBadField,       // an enumerated value that is not defined
  kBadVersion,     // heartbeat of another protocol version
};
const char* decodeErrorName(DecodeError error);
const char* encodeErrorName(EncodeError error);

// On success *out holds the message; on error *out is untouched.
DecodeError decode(const CanFrame& frame, JointAnglesFrame* out);
DecodeError decode(const CanFrame& frame, TouchFrame* out);
DecodeError decode(const CanFrame& frame, ValveCommandFrame* out);
DecodeError decode(const CanFrame& frame, SensorFrame* out);  // pressure or length
DecodeError decode(const CanFrame& frame, SupplyFrame* out);
DecodeError decode(const CanFrame& frame, HeartbeatFrame* out);
DecodeError decode(const CanFrame& frame, EstopFrame* out);
DecodeError decode(const CanFrame& frame, FaultFrame* out);
DecodeError decode(const CanFrame& frame, Message* out);  // any type

// ---------------------------------------------------------------- sequence counters
struct SequenceStats {
  std::uint64_t frames = 0;      // every frame observed
  std::uint64_t lost = 0;        // numbers skipped and not (yet) seen late
  std::uint64_t duplicates = 0;  // a number seen again within the window
  std::uint64_t reordered = 0;   // a skipped number that arrived late (no longer lost)
  std::uint64_t resyncs = 0;     // a jump back beyond the window: counting restarted there
};

enum class SequenceVerdict : std::uint8_t { kFirst, kInOrder, kGap, kDuplicate, kLate, kResync };

// One stream's 8-bit counter (one CAN identifier). Wrap-around aware: a step forward of
// 1..127 is new (the numbers in between count as lost), a step back within the last
// kWindow numbers is a duplicate or a late frame, anything else restarts the count
// (the sender rebooted, or more than 127 frames went missing: the two look alike).
class SequenceTracker {
 public:
  static constexpr int kWindow = 64;
  SequenceVerdict observe(std::uint8_t seq);
  void reset();  // forget the stream (keeps nothing, including the statistics)
  const SequenceStats& stats() const { return stats_; }

 private:
  void restart(std::uint8_t seq);

  bool started_ = false;
  std::uint8_t last_ = 0;
  std::uint64_t seen_ = 0;  // bit k: number last_ - k has been received
  int span_ = 0;            // numbers counted since the start or resync, up to kWindow
  SequenceStats stats_;
};

}  // namespace adroit::driver::can
