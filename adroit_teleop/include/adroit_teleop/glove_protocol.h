// CyberGlove-style serial protocol, the subset this package implements (docs/glove_protocol.md):
// host commands, the frames the glove sends back (records, error records, the sensor-count
// reply), encoders for both directions, and streaming decoders that resynchronise on garbage.
//
// The decoders work byte by byte on a window no longer than one frame, so their memory is
// bounded whatever the input, and a frame split across reads at any position decodes the same.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace adroit::teleop {

// --- bytes on the wire ---------------------------------------------------------------------
constexpr std::uint8_t kPolledHeader = 'G';   // host: request one record; glove: a polled record
constexpr std::uint8_t kStreamHeader = 'S';   // host: start streaming;     glove: a streamed record
constexpr std::uint8_t kStopStream = 0x03;    // host: stop streaming (Ctrl-C)
constexpr std::uint8_t kQueryHeader = '?';    // host: "?S" query;          glove: "?S" count 0
constexpr std::uint8_t kErrorHeader = 'e';    // glove: error record 'e' code 0
constexpr std::uint8_t kTerminator = 0x00;    // ends every glove frame; never a sensor value

constexpr int kSensors18 = 18;
constexpr int kSensors22 = 22;
constexpr int kMaxSensors = 22;
constexpr int kMaxFrameBytes = 1 + kMaxSensors + 1;  // header, values, terminator

// True for the two glove models the protocol knows (18 and 22 sensors).
bool validSensorCount(int n);

// Error codes of an error record ('e' code 0).
enum class GloveError : std::uint8_t {
  kGloveUnplugged = 'g',        // the glove is not plugged into its interface unit
  kSamplePeriodTooShort = 's',  // streaming faster than the unit can sample
  kUnknownCommand = '?',        // the host sent a command the unit does not know
};
bool knownGloveError(std::uint8_t code);
const char* gloveErrorText(GloveError code);  // "glove not plugged in", ...

// --- frames from the glove -----------------------------------------------------------------
enum class FrameType : std::uint8_t {
  kPolledRecord,    // 'G' values 0, answer to a 'G' command
  kStreamedRecord,  // 'S' values 0, sent at the streaming rate after an 'S' command
  kError,           // 'e' code 0
  kSensorCount,     // '?' 'S' count 0, answer to a "?S" query
};

struct GloveFrame {
  FrameType type = FrameType::kPolledRecord;
  std::uint64_t offset = 0;    // position of the header byte among all bytes fed to the parser
  std::uint64_t sequence = 0;  // records only: 0 for the first record decoded, 1 for the next...
  int count = 0;               // records: number of sensor values; kSensorCount: the count reported
  std::array<std::uint8_t, kMaxSensors> raw{};  // records: the sensor bytes, 1..255
  GloveError error = GloveError::kUnknownCommand;  // kError only

  bool isRecord() const { return type == FrameType::kPolledRecord || type == FrameType::kStreamedRecord; }
};

// Sensor values as the rest of the package uses them: raw / 255, so a value lies in
// (0, 1] and the calibration's regularisation weight has the same meaning for every glove.
double sensorValue(std::uint8_t raw);
// Writes frame.count values (raw / 255) to out.
void sensorValues(const GloveFrame& frame, double* out);
std::vector<double> sensorValues(const GloveFrame& frame);

// Why the parser threw a candidate frame away.
enum class RejectReason : std::uint8_t {
  kEarlyTerminator,    // a 0 where a value was expected: the frame is too short (or corrupt)
  kMissingTerminator,  // no 0 where the frame should end: too long, or header was garbage
  kBadErrorCode,       // 'e' followed by a code this protocol does not define
  kBadCountReply,      // '?' not followed by 'S' and a valid sensor count
};
constexpr int kRejectReasons = 4;
const char* rejectReasonName(RejectReason reason);  // "early_terminator", ...

struct ParserStats {
  std::uint64_t bytes = 0;          // every byte fed
  std::uint64_t frame_bytes = 0;    // bytes of accepted frames
  std::uint64_t records = 0;        // polled + streamed records accepted
  std::uint64_t error_records = 0;  // 'e' frames accepted
  std::uint64_t count_replies = 0;  // "?S" replies accepted
  std::uint64_t garbage_bytes = 0;  // bytes skipped while looking for a header (rejected frames'
                                    // bytes included, unless they start a later frame)
  std::array<std::uint64_t, kRejectReasons> rejected{};  // candidate frames, by reason

  std::uint64_t rejectedTotal() const;
  std::uint64_t rejectedFor(RejectReason r) const { return rejected[static_cast<int>(r)]; }
};

// Streaming decoder of what the glove sends. Every fed byte ends up in exactly one of:
// an accepted frame, garbage_bytes, or the pending window (at most one frame long), so
// stats().bytes == frame bytes + garbage_bytes + pending().
//
// Resynchronisation: a candidate frame starts at any header byte. When it turns out wrong
// (a 0 too early, no 0 where the frame must end, a bad code), it is rejected and scanning
// restarts one byte after its header, so a real frame hidden behind a garbage header byte is
// still found. Records have a fixed length and sensor bytes are never 0, so a candidate that
// starts inside a record always meets that record's terminator too early and is rejected.
class GloveParser {
 public:
  // sensors: 18 or 22 (std::invalid_argument otherwise).
  explicit GloveParser(int sensors);

  // Decodes bytes, appending complete frames to out (which is not cleared). Returns how many
  // frames were appended. Allocates only when out has to grow.
  std::size_t feed(const std::uint8_t* bytes, std::size_t n, std::vector<GloveFrame>& out);
  std::vector<GloveFrame> feed(const std::uint8_t* bytes, std::size_t n);

  // Changes the record length, e.g. after a "?S" reply. Not done automatically: a reply
  // decoded while resynchronising on garbage must not change how every later record is read.
  // Drops the pending window (counted as garbage).
  void setSensorCount(int sensors);
  int sensorCount() const { return sensors_; }

  // Forgets the pending window (counted as garbage), e.g. after reopening the port.
  void resetWindow();
  std::size_t pending() const { return window_size_; }
  const ParserStats& stats() const { return stats_; }

 private:
  enum class Check { kIncomplete, kComplete, kReject };
  // Looks at the candidate frame at the front of the window (its first byte is a header).
  // kComplete sets *length, kReject sets *reason.
  Check check(std::size_t* length, RejectReason* reason) const;
  void emit(std::size_t length, std::vector<GloveFrame>& out);
  void dropFront(std::size_t n);

  int sensors_;
  std::array<std::uint8_t, kMaxFrameBytes> window_{};
  std::size_t window_size_ = 0;
  std::uint64_t window_offset_ = 0;  // stream position of window_[0]
  ParserStats stats_;
};

// --- commands from the host ----------------------------------------------------------------
enum class GloveCommand : std::uint8_t {
  kPoll,              // 'G'
  kStartStream,       // 'S'
  kStopStream,        // 0x03
  kQuerySensorCount,  // '?' 'S'
  kUnknown,           // anything else (one byte, or '?' and the byte after it)
};

// Streaming decoder of host commands (the glove side, used by the emulator). Its only state
// is a pending '?' waiting for its second byte.
class CommandParser {
 public:
  std::size_t feed(const std::uint8_t* bytes, std::size_t n, std::vector<GloveCommand>& out);
  bool pendingQuery() const { return pending_query_; }
  void reset() { pending_query_ = false; }

 private:
  bool pending_query_ = false;
};

// --- encoders (append to out) --------------------------------------------------------------
// A record: header ('G' polled, 'S' streamed), the values, the terminator. Throws
// std::invalid_argument for a sensor count other than 18/22 or a value of 0.
void appendRecord(std::vector<std::uint8_t>& out, bool streamed, const std::uint8_t* values, int count);
void appendError(std::vector<std::uint8_t>& out, GloveError code);
// '?' 'S' count 0. Throws std::invalid_argument for a count other than 18/22.
void appendCountReply(std::vector<std::uint8_t>& out, int count);
void appendCommand(std::vector<std::uint8_t>& out, GloveCommand command);  // kUnknown: invalid_argument

// The same, returned as a new buffer.
std::vector<std::uint8_t> encodeRecord(bool streamed, const std::vector<std::uint8_t>& values);
std::vector<std::uint8_t> encodeError(GloveError code);
std::vector<std::uint8_t> encodeCountReply(int count);
std::vector<std::uint8_t> encodeCommand(GloveCommand command);

}  // namespace adroit::teleop
