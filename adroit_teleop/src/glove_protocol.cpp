#include "adroit_teleop/glove_protocol.h"

#include <algorithm>
#include <cstring>
#include <stdexcept>

namespace adroit::teleop {

bool validSensorCount(int n) { return n == kSensors18 || n == kSensors22; }

bool knownGloveError(std::uint8_t code) {
  return code == static_cast<std::uint8_t>(GloveError::kGloveUnplugged) ||
         code == static_cast<std::uint8_t>(GloveError::kSamplePeriodTooShort) ||
         code == static_cast<std::uint8_t>(GloveError::kUnknownCommand);
}

const char* gloveErrorText(GloveError code) {
  switch (code) {
    case GloveError::kGloveUnplugged: return "glove not plugged into the interface unit";
    case GloveError::kSamplePeriodTooShort: return "sample period too short";
    case GloveError::kUnknownCommand: return "unknown command";
  }
  return "unknown error code";
}

double sensorValue(std::uint8_t raw) { return raw / 255.0; }

void sensorValues(const GloveFrame& frame, double* out) {
  for (int i = 0; i < frame.count; ++i) out[i] = sensorValue(frame.raw[i]);
}

std::vector<double> sensorValues(const GloveFrame& frame) {
  std::vector<double> v(frame.isRecord() ? frame.count : 0);
  if (!v.empty()) sensorValues(frame, v.data());
  return v;
}

const char* rejectReasonName(RejectReason reason) {
  switch (reason) {
    case RejectReason::kEarlyTerminator: return "early_terminator";
    case RejectReason::kMissingTerminator: return "missing_terminator";
    case RejectReason::kBadErrorCode: return "bad_error_code";
    case RejectReason::kBadCountReply: return "bad_count_reply";
  }
  return "unknown";
}

std::uint64_t ParserStats::rejectedTotal() const {
  std::uint64_t total = 0;
  for (std::uint64_t r : rejected) total += r;
  return total;
}

// --- GloveParser ---------------------------------------------------------------------------

namespace {

bool isHeader(std::uint8_t b) {
  return b == kPolledHeader || b == kStreamHeader || b == kErrorHeader || b == kQueryHeader;
}

}  // namespace

GloveParser::GloveParser(int sensors) : sensors_(sensors) {
  if (!validSensorCount(sensors))
    throw std::invalid_argument("glove parser: sensor count must be 18 or 22, got " + std::to_string(sensors));
}

void GloveParser::setSensorCount(int sensors) {
  if (!validSensorCount(sensors))
    throw std::invalid_argument("glove parser: sensor count must be 18 or 22, got " + std::to_string(sensors));
  sensors_ = sensors;
  resetWindow();
}

void GloveParser::resetWindow() {
  stats_.garbage_bytes += window_size_;
  dropFront(window_size_);
}

void GloveParser::dropFront(std::size_t n) {
  std::memmove(window_.data(), window_.data() + n, window_size_ - n);
  window_size_ -= n;
  window_offset_ += n;
}

GloveParser::Check GloveParser::check(std::size_t* length, RejectReason* reason) const {
  const std::uint8_t header = window_[0];
  const std::size_t len = header == kErrorHeader   ? 3
                          : header == kQueryHeader ? 4
                                                   : static_cast<std::size_t>(sensors_) + 2;
  const std::size_t n = std::min(window_size_, len);
  for (std::size_t i = 1; i < n; ++i) {
    const std::uint8_t b = window_[i];
    if (i == len - 1) {
      if (b != kTerminator) {
        *reason = RejectReason::kMissingTerminator;
        return Check::kReject;
      }
      *length = len;
      return Check::kComplete;
    }
    if (b == kTerminator) {
      *reason = RejectReason::kEarlyTerminator;
      return Check::kReject;
    }
    if (header == kErrorHeader && !knownGloveError(b)) {
      *reason = RejectReason::kBadErrorCode;
      return Check::kReject;
    }
    if (header == kQueryHeader && ((i == 1 && b != 'S') || (i == 2 && !validSensorCount(b)))) {
      *reason = RejectReason::kBadCountReply;
      return Check::kReject;
    }
  }
  return Check::kIncomplete;
}

void GloveParser::emit(std::size_t length, std::vector<GloveFrame>& out) {
  GloveFrame f;
  f.offset = window_offset_;
  switch (window_[0]) {
    case kErrorHeader:
      f.type = FrameType::kError;
      f.error = static_cast<GloveError>(window_[1]);
      ++stats_.error_records;
      break;
    case kQueryHeader:
      f.type = FrameType::kSensorCount;
      f.count = window_[2];
      ++stats_.count_replies;
      break;
    default:
      f.type = window_[0] == kStreamHeader ? FrameType::kStreamedRecord : FrameType::kPolledRecord;
      f.count = sensors_;
      std::copy_n(window_.begin() + 1, sensors_, f.raw.begin());
      f.sequence = stats_.records++;
      break;
  }
  stats_.frame_bytes += length;
  out.push_back(f);
  dropFront(length);
}

std::size_t GloveParser::feed(const std::uint8_t* bytes, std::size_t n, std::vector<GloveFrame>& out) {
  const std::size_t before = out.size();
  for (std::size_t k = 0; k < n; ++k) {
    // The window never holds a whole undecided frame: each byte either completes, rejects
    // or extends the candidate at its front, so there is always room for one more byte.
    window_[window_size_++] = bytes[k];
    ++stats_.bytes;
    while (window_size_ > 0) {
      if (!isHeader(window_[0])) {
        ++stats_.garbage_bytes;
        dropFront(1);
        continue;
      }
      std::size_t length = 0;
      RejectReason reason{};
      const Check c = check(&length, &reason);
      if (c == Check::kIncomplete) break;
      if (c == Check::kComplete) {
        emit(length, out);
      } else {
        // Rescan from the byte after this header: a real frame may start inside.
        ++stats_.rejected[static_cast<int>(reason)];
        ++stats_.garbage_bytes;
        dropFront(1);
      }
    }
  }
  return out.size() - before;
}

std::vector<GloveFrame> GloveParser::feed(const std::uint8_t* bytes, std::size_t n) {
  std::vector<GloveFrame> out;
  feed(bytes, n, out);
  return out;
}

// --- CommandParser -------------------------------------------------------------------------

std::size_t CommandParser::feed(const std::uint8_t* bytes, std::size_t n, std::vector<GloveCommand>& out) {
  const std::size_t before = out.size();
  for (std::size_t k = 0; k < n; ++k) {
    const std::uint8_t b = bytes[k];
    if (pending_query_) {
      pending_query_ = false;
      out.push_back(b == 'S' ? GloveCommand::kQuerySensorCount : GloveCommand::kUnknown);
      continue;
    }
    switch (b) {
      case kPolledHeader: out.push_back(GloveCommand::kPoll); break;
      case kStreamHeader: out.push_back(GloveCommand::kStartStream); break;
      case kStopStream: out.push_back(GloveCommand::kStopStream); break;
      case kQueryHeader: pending_query_ = true; break;
      default: out.push_back(GloveCommand::kUnknown); break;
    }
  }
  return out.size() - before;
}

// --- encoders ------------------------------------------------------------------------------

void appendRecord(std::vector<std::uint8_t>& out, bool streamed, const std::uint8_t* values, int count) {
  if (!validSensorCount(count))
    throw std::invalid_argument("glove record: sensor count must be 18 or 22, got " + std::to_string(count));
  for (int i = 0; i < count; ++i)
    if (values[i] == kTerminator)
      throw std::invalid_argument("glove record: sensor value " + std::to_string(i) + " is 0 (reserved)");
  out.push_back(streamed ? kStreamHeader : kPolledHeader);
  out.insert(out.end(), values, values + count);
  out.push_back(kTerminator);
}

void appendError(std::vector<std::uint8_t>& out, GloveError code) {
  out.push_back(kErrorHeader);
  out.push_back(static_cast<std::uint8_t>(code));
  out.push_back(kTerminator);
}

void appendCountReply(std::vector<std::uint8_t>& out, int count) {
  if (!validSensorCount(count))
    throw std::invalid_argument("glove count reply: sensor count must be 18 or 22, got " + std::to_string(count));
  out.push_back(kQueryHeader);
  out.push_back('S');
  out.push_back(static_cast<std::uint8_t>(count));
  out.push_back(kTerminator);
}

void appendCommand(std::vector<std::uint8_t>& out, GloveCommand command) {
  switch (command) {
    case GloveCommand::kPoll: out.push_back(kPolledHeader); return;
    case GloveCommand::kStartStream: out.push_back(kStreamHeader); return;
    case GloveCommand::kStopStream: out.push_back(kStopStream); return;
    case GloveCommand::kQuerySensorCount:
      out.push_back(kQueryHeader);
      out.push_back('S');
      return;
    case GloveCommand::kUnknown: break;
  }
  throw std::invalid_argument("glove command: cannot encode an unknown command");
}

std::vector<std::uint8_t> encodeRecord(bool streamed, const std::vector<std::uint8_t>& values) {
  std::vector<std::uint8_t> out;
  appendRecord(out, streamed, values.data(), static_cast<int>(values.size()));
  return out;
}

std::vector<std::uint8_t> encodeError(GloveError code) {
  std::vector<std::uint8_t> out;
  appendError(out, code);
  return out;
}

std::vector<std::uint8_t> encodeCountReply(int count) {
  std::vector<std::uint8_t> out;
  appendCountReply(out, count);
  return out;
}

std::vector<std::uint8_t> encodeCommand(GloveCommand command) {
  std::vector<std::uint8_t> out;
  appendCommand(out, command);
  return out;
}

}  // namespace adroit::teleop
