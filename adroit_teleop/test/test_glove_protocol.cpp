// The glove protocol: frames written out by hand decode as the spec (docs/glove_protocol.md)
// says, the encoders produce exactly those bytes, and the parser survives anything: garbage,
// corrupt and truncated frames, random bytes, and any split of the input across reads.
#include <adroit_teleop/glove_protocol.h>
#include <gtest/gtest.h>

#include <numeric>
#include <random>

using namespace adroit::teleop;
using Bytes = std::vector<std::uint8_t>;

namespace {

Bytes cat(std::initializer_list<Bytes> parts) {
  Bytes out;
  for (const Bytes& p : parts) out.insert(out.end(), p.begin(), p.end());
  return out;
}

// A record written out by hand: header, the values first..first+n-1, terminator.
Bytes handRecord(char header, int n, int first) {
  Bytes b{static_cast<std::uint8_t>(header)};
  for (int i = 0; i < n; ++i) b.push_back(static_cast<std::uint8_t>(first + i));
  b.push_back(0);
  return b;
}

std::vector<GloveFrame> decodeAll(int sensors, const Bytes& bytes, GloveParser* keep = nullptr) {
  GloveParser p(sensors);
  auto frames = p.feed(bytes.data(), bytes.size());
  if (keep) *keep = p;
  return frames;
}

// Frames compared on everything the parser reports.
void expectSameFrames(const std::vector<GloveFrame>& a, const std::vector<GloveFrame>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].type, b[i].type) << i;
    EXPECT_EQ(a[i].offset, b[i].offset) << i;
    EXPECT_EQ(a[i].sequence, b[i].sequence) << i;
    EXPECT_EQ(a[i].count, b[i].count) << i;
    EXPECT_EQ(a[i].raw, b[i].raw) << i;
    EXPECT_EQ(a[i].error, b[i].error) << i;
  }
}

// Every byte is in a frame, in garbage, or pending; the window never holds a whole frame.
void expectAccounted(const GloveParser& p) {
  const ParserStats& s = p.stats();
  EXPECT_EQ(s.bytes, s.frame_bytes + s.garbage_bytes + p.pending());
  EXPECT_LT(p.pending(), static_cast<std::size_t>(p.sensorCount() + 2));
}

}  // namespace

TEST(GloveProtocol, HandWrittenPolledRecord18) {
  const Bytes bytes = handRecord('G', 18, 1);  // 'G' 1 2 ... 18 0
  ASSERT_EQ(bytes.size(), 20u);
  GloveParser p(18);
  const auto frames = p.feed(bytes.data(), bytes.size());
  ASSERT_EQ(frames.size(), 1u);
  EXPECT_EQ(frames[0].type, FrameType::kPolledRecord);
  EXPECT_TRUE(frames[0].isRecord());
  EXPECT_EQ(frames[0].count, 18);
  EXPECT_EQ(frames[0].offset, 0u);
  EXPECT_EQ(frames[0].sequence, 0u);
  for (int i = 0; i < 18; ++i) EXPECT_EQ(frames[0].raw[i], i + 1);
  EXPECT_EQ(p.stats().records, 1u);
  EXPECT_EQ(p.stats().garbage_bytes, 0u);
  EXPECT_EQ(p.pending(), 0u);
}

TEST(GloveProtocol, HandWrittenStreamAndReplies22) {
  // Garbage, two streamed records, an error record, a sensor-count reply.
  const Bytes bytes = cat({{0x01, 0xff, 0x7f},
                           handRecord('S', 22, 200),
                           handRecord('S', 22, 10),
                           {'e', 'g', 0},
                           {'?', 'S', 22, 0}});
  GloveParser p(22);
  const auto f = p.feed(bytes.data(), bytes.size());
  ASSERT_EQ(f.size(), 4u);
  EXPECT_EQ(f[0].type, FrameType::kStreamedRecord);
  EXPECT_EQ(f[0].offset, 3u);
  EXPECT_EQ(f[0].raw[0], 200);
  EXPECT_EQ(f[0].raw[21], 221);
  EXPECT_EQ(f[1].offset, 3u + 24u);
  EXPECT_EQ(f[1].sequence, 1u);
  EXPECT_EQ(f[1].raw[5], 15);
  EXPECT_EQ(f[2].type, FrameType::kError);
  EXPECT_EQ(f[2].error, GloveError::kGloveUnplugged);
  EXPECT_EQ(f[3].type, FrameType::kSensorCount);
  EXPECT_EQ(f[3].count, 22);
  EXPECT_EQ(p.stats().garbage_bytes, 3u);
  EXPECT_EQ(p.stats().records, 2u);
  EXPECT_EQ(p.stats().error_records, 1u);
  EXPECT_EQ(p.stats().count_replies, 1u);
  EXPECT_EQ(p.stats().rejectedTotal(), 0u);
  expectAccounted(p);
}

TEST(GloveProtocol, EncodersWriteTheSpecBytes) {
  Bytes values(18);
  std::iota(values.begin(), values.end(), 1);
  EXPECT_EQ(encodeRecord(false, values), handRecord('G', 18, 1));
  values.assign(22, 0);
  std::iota(values.begin(), values.end(), 100);
  EXPECT_EQ(encodeRecord(true, values), handRecord('S', 22, 100));
  EXPECT_EQ(encodeError(GloveError::kGloveUnplugged), (Bytes{'e', 'g', 0}));
  EXPECT_EQ(encodeError(GloveError::kSamplePeriodTooShort), (Bytes{'e', 's', 0}));
  EXPECT_EQ(encodeError(GloveError::kUnknownCommand), (Bytes{'e', '?', 0}));
  EXPECT_EQ(encodeCountReply(18), (Bytes{'?', 'S', 18, 0}));
  EXPECT_EQ(encodeCommand(GloveCommand::kPoll), (Bytes{'G'}));
  EXPECT_EQ(encodeCommand(GloveCommand::kStartStream), (Bytes{'S'}));
  EXPECT_EQ(encodeCommand(GloveCommand::kStopStream), (Bytes{0x03}));
  EXPECT_EQ(encodeCommand(GloveCommand::kQuerySensorCount), (Bytes{'?', 'S'}));
}

TEST(GloveProtocol, EncodersRefuseWhatTheProtocolCannotCarry) {
  Bytes values(22, 7);
  values[4] = 0;  // 0 is the terminator
  EXPECT_THROW(encodeRecord(true, values), std::invalid_argument);
  EXPECT_THROW(encodeRecord(true, Bytes(20, 7)), std::invalid_argument);
  EXPECT_THROW(encodeCountReply(21), std::invalid_argument);
  EXPECT_THROW(encodeCommand(GloveCommand::kUnknown), std::invalid_argument);
  EXPECT_THROW(GloveParser(0), std::invalid_argument);
  EXPECT_THROW(GloveParser(23), std::invalid_argument);
}

TEST(GloveProtocol, RoundTripBothSizesBothKinds) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> value(1, 255);
  for (int n : {18, 22}) {
    for (bool streamed : {false, true}) {
      Bytes stream;
      std::vector<Bytes> sent;
      for (int r = 0; r < 50; ++r) {
        Bytes v(n);
        for (auto& x : v) x = static_cast<std::uint8_t>(value(rng));
        v[r % n] = 255;  // the extremes too
        v[(r + 1) % n] = 1;
        appendRecord(stream, streamed, v.data(), n);
        sent.push_back(v);
      }
      GloveParser p(n);
      const auto frames = p.feed(stream.data(), stream.size());
      ASSERT_EQ(frames.size(), sent.size());
      for (std::size_t r = 0; r < sent.size(); ++r) {
        EXPECT_EQ(frames[r].type, streamed ? FrameType::kStreamedRecord : FrameType::kPolledRecord);
        EXPECT_EQ(frames[r].sequence, r);
        EXPECT_EQ(frames[r].offset, r * (n + 2));
        EXPECT_TRUE(std::equal(sent[r].begin(), sent[r].end(), frames[r].raw.begin())) << "record " << r;
      }
      EXPECT_EQ(p.stats().garbage_bytes, 0u);
      EXPECT_EQ(p.stats().rejectedTotal(), 0u);
    }
  }
}

TEST(GloveProtocol, SensorValuesAreRawOver255) {
  GloveFrame f;
  f.type = FrameType::kStreamedRecord;
  f.count = 18;
  f.raw.fill(51);
  f.raw[0] = 255;
  f.raw[1] = 1;
  const std::vector<double> v = sensorValues(f);
  ASSERT_EQ(v.size(), 18u);
  EXPECT_DOUBLE_EQ(v[0], 1.0);
  EXPECT_DOUBLE_EQ(v[1], 1.0 / 255);
  EXPECT_DOUBLE_EQ(v[2], 0.2);
  f.type = FrameType::kError;
  EXPECT_TRUE(sensorValues(f).empty());
}

TEST(GloveProtocol, ZeroInsideDataIsAnEarlyTerminator) {
  Bytes bad = handRecord('S', 22, 110);  // 110..131: no header byte among the values
  bad[6] = 0;  // value 6 of 22 is 0: the frame ends after 5 values
  const Bytes good = handRecord('S', 22, 30);
  GloveParser p(22);
  const auto f = p.feed(cat({bad, good}).data(), bad.size() + good.size());
  ASSERT_EQ(f.size(), 1u);
  EXPECT_EQ(f[0].raw[0], 30);
  EXPECT_EQ(f[0].offset, bad.size());
  EXPECT_EQ(p.stats().rejectedFor(RejectReason::kEarlyTerminator), 1u);
  EXPECT_EQ(p.stats().rejectedTotal(), 1u);
  EXPECT_EQ(p.stats().garbage_bytes, bad.size());
  expectAccounted(p);
}

TEST(GloveProtocol, MissingTerminatorIsRejected) {
  Bytes bad = handRecord('G', 18, 110);  // 110..127: no header byte among the values
  bad.back() = 0x07;  // one value too many, or a corrupt terminator
  const Bytes good = handRecord('G', 18, 30);
  GloveParser p(18);
  const Bytes all = cat({bad, good});
  const auto f = p.feed(all.data(), all.size());
  ASSERT_EQ(f.size(), 1u);
  EXPECT_EQ(f[0].raw[17], 47);
  EXPECT_EQ(p.stats().rejectedFor(RejectReason::kMissingTerminator), 1u);
  EXPECT_EQ(p.stats().rejectedTotal(), 1u);
  EXPECT_EQ(p.stats().garbage_bytes, bad.size());
}

TEST(GloveProtocol, TruncatedFrameFollowedByRecord) {
  // A record cut off after 10 values (the line dropped the rest), then a complete one. The
  // truncated frame swallows the real header; rescanning after the rejection finds it.
  Bytes cut = handRecord('S', 22, 110);
  cut.resize(11);
  const Bytes good = handRecord('S', 22, 40);
  GloveParser p(22);
  const Bytes all = cat({cut, good, good});
  const auto f = p.feed(all.data(), all.size());
  ASSERT_EQ(f.size(), 2u);
  EXPECT_EQ(f[0].offset, 11u);
  EXPECT_EQ(f[0].raw[0], 40);
  EXPECT_EQ(f[0].sequence, 0u);
  EXPECT_EQ(f[1].sequence, 1u);
  EXPECT_EQ(p.stats().rejectedFor(RejectReason::kMissingTerminator), 1u);
  EXPECT_EQ(p.stats().rejectedTotal(), 1u);
  EXPECT_EQ(p.stats().garbage_bytes, 11u);
}

TEST(GloveProtocol, HeaderByteInsideGarbageDoesNotHideTheRecord) {
  // 'S' 'G' and 'e' occur in garbage; the real record right after must still decode.
  const Bytes all = cat({{'S', 5, 'G', 9, 'e'}, handRecord('G', 18, 60)});
  GloveParser p(18);
  const auto f = p.feed(all.data(), all.size());
  ASSERT_EQ(f.size(), 1u);
  EXPECT_EQ(f[0].type, FrameType::kPolledRecord);
  EXPECT_EQ(f[0].offset, 5u);
  EXPECT_EQ(f[0].raw[0], 60);
  EXPECT_EQ(p.stats().garbage_bytes, 5u);
  expectAccounted(p);
}

TEST(GloveProtocol, BadErrorCodeAndBadCountReply) {
  GloveParser p(22);
  const Bytes all = {'e', 'x', 0, '?', 'S', 20, 0, '?', 'Q', 22, 0, 'e', 's', 0};
  const auto f = p.feed(all.data(), all.size());
  ASSERT_EQ(f.size(), 1u);
  EXPECT_EQ(f[0].type, FrameType::kError);
  EXPECT_EQ(f[0].error, GloveError::kSamplePeriodTooShort);
  EXPECT_EQ(f[0].offset, 11u);
  EXPECT_EQ(p.stats().rejectedFor(RejectReason::kBadErrorCode), 1u);
  EXPECT_EQ(p.stats().rejectedFor(RejectReason::kBadCountReply), 2u);
  EXPECT_EQ(p.stats().error_records, 1u);
}

TEST(GloveProtocol, WrongSensorCountRejectsEverythingUntilSet) {
  // An 18-sensor glove read as a 22-sensor one: every record ends early.
  Bytes stream;
  for (int r = 0; r < 5; ++r) stream = cat({stream, handRecord('S', 18, 100 + r)});
  GloveParser p(22);
  EXPECT_TRUE(p.feed(stream.data(), stream.size()).empty());
  EXPECT_GE(p.stats().rejectedFor(RejectReason::kEarlyTerminator), 5u);
  EXPECT_EQ(p.stats().records, 0u);
  p.setSensorCount(18);
  const auto f = p.feed(stream.data(), stream.size());
  ASSERT_EQ(f.size(), 5u);
  EXPECT_EQ(f[4].raw[0], 104);
  EXPECT_EQ(f[4].count, 18);
  expectAccounted(p);
}

TEST(GloveProtocol, EverySplitPositionGivesTheSameFrames) {
  const Bytes all = cat({{0x33, 'S'},
                         handRecord('S', 22, 1),
                         {'e', 'g', 0},
                         handRecord('G', 22, 200),
                         {'?', 'S', 18, 0},
                         {0, 0, 'e'},
                         handRecord('S', 22, 70)});
  GloveParser whole_parser(22);
  const auto whole = decodeAll(22, all, &whole_parser);
  ASSERT_EQ(whole.size(), 5u);  // 3 records, 1 error, 1 count reply
  for (std::size_t cut = 0; cut <= all.size(); ++cut) {
    GloveParser p(22);
    std::vector<GloveFrame> frames;
    p.feed(all.data(), cut, frames);
    p.feed(all.data() + cut, all.size() - cut, frames);
    SCOPED_TRACE("split at " + std::to_string(cut));
    expectSameFrames(frames, whole);
    EXPECT_EQ(p.stats().garbage_bytes, whole_parser.stats().garbage_bytes);
    EXPECT_EQ(p.stats().rejected, whole_parser.stats().rejected);
  }
  // And one byte at a time.
  GloveParser p(22);
  std::vector<GloveFrame> frames;
  for (std::uint8_t b : all) p.feed(&b, 1, frames);
  expectSameFrames(frames, whole);
}

TEST(GloveProtocol, RandomBytesNeverBreakTheParser) {
  // Whatever comes in: no crash (the sanitizer build checks for UB), bounded state, every
  // byte accounted for, and every frame reported is really in the input at its offset.
  for (unsigned seed = 1; seed <= 300; ++seed) {
    std::mt19937 rng(seed);
    // Bytes biased towards the interesting ones (headers, 0, valid codes and counts).
    const Bytes alphabet = {0, 0, 'G', 'S', 'e', '?', 'g', 's', 18, 22, 1, 255};
    std::uniform_int_distribution<int> pick(0, 2 * static_cast<int>(alphabet.size()) - 1), any(0, 255);
    Bytes input(std::uniform_int_distribution<int>(0, 3000)(rng));
    for (auto& b : input) {
      const int k = pick(rng);
      b = k < static_cast<int>(alphabet.size()) ? alphabet[k] : static_cast<std::uint8_t>(any(rng));
    }
    const int sensors = seed % 2 ? 18 : 22;
    GloveParser p(sensors);
    std::vector<GloveFrame> frames;
    std::size_t at = 0;
    while (at < input.size()) {
      const std::size_t n = std::min<std::size_t>(input.size() - at, std::uniform_int_distribution<int>(0, 40)(rng));
      p.feed(input.data() + at, n, frames);
      at += n;
      ASSERT_LT(p.pending(), static_cast<std::size_t>(kMaxFrameBytes));
    }
    SCOPED_TRACE("seed " + std::to_string(seed));
    EXPECT_EQ(p.stats().bytes, input.size());
    expectAccounted(p);
    for (const GloveFrame& f : frames) {
      ASSERT_LT(f.offset, input.size());
      const std::uint8_t* at_offset = input.data() + f.offset;
      switch (f.type) {
        case FrameType::kPolledRecord:
        case FrameType::kStreamedRecord:
          ASSERT_LE(f.offset + sensors + 2, input.size());
          EXPECT_EQ(at_offset[0], f.type == FrameType::kStreamedRecord ? 'S' : 'G');
          for (int i = 0; i < sensors; ++i) {
            EXPECT_EQ(at_offset[1 + i], f.raw[i]);
            EXPECT_NE(f.raw[i], 0);
          }
          EXPECT_EQ(at_offset[sensors + 1], 0);
          break;
        case FrameType::kError:
          EXPECT_EQ(at_offset[0], 'e');
          EXPECT_EQ(at_offset[1], static_cast<std::uint8_t>(f.error));
          EXPECT_TRUE(knownGloveError(at_offset[1]));
          EXPECT_EQ(at_offset[2], 0);
          break;
        case FrameType::kSensorCount:
          EXPECT_EQ(at_offset[0], '?');
          EXPECT_EQ(at_offset[1], 'S');
          EXPECT_EQ(at_offset[2], f.count);
          EXPECT_EQ(at_offset[3], 0);
          break;
      }
    }
  }
}

TEST(GloveProtocol, RecordsSurviveArbitraryGarbageBetweenThem) {
  // Garbage between records (zeros and header bytes included) never costs a record: a
  // candidate frame starting in garbage cannot end on a record's terminator. Bursts are
  // shorter than a record, so none can hold a whole well-formed record of its own.
  for (unsigned seed = 1; seed <= 100; ++seed) {
    std::mt19937 rng(seed);
    const int sensors = seed % 2 ? 22 : 18;
    std::uniform_int_distribution<int> value(1, 255), byte(0, 255), burst(0, sensors + 1);
    const Bytes nasty = {0, 'G', 'S', 'e', '?', 'g', 's', 22, 18};
    Bytes stream;
    std::vector<Bytes> sent;
    for (int r = 0; r < 40; ++r) {
      const int g = burst(rng);
      for (int i = 0; i < g; ++i)
        stream.push_back(byte(rng) < 128 ? nasty[byte(rng) % nasty.size()] : static_cast<std::uint8_t>(byte(rng)));
      Bytes v(sensors);
      for (auto& x : v) x = static_cast<std::uint8_t>(value(rng));
      appendRecord(stream, byte(rng) < 128, v.data(), sensors);
      sent.push_back(v);
    }
    GloveParser p(sensors);
    std::vector<GloveFrame> frames;
    for (std::size_t at = 0; at < stream.size(); at += 7)
      p.feed(stream.data() + at, std::min<std::size_t>(7, stream.size() - at), frames);
    std::vector<GloveFrame> records;
    for (const GloveFrame& f : frames)
      if (f.isRecord()) records.push_back(f);
    SCOPED_TRACE("seed " + std::to_string(seed));
    ASSERT_EQ(records.size(), sent.size());
    for (std::size_t r = 0; r < sent.size(); ++r)
      EXPECT_TRUE(std::equal(sent[r].begin(), sent[r].end(), records[r].raw.begin())) << "record " << r;
  }
}

TEST(GloveProtocol, MemoryStaysBoundedOnEndlessGarbage) {
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> byte(0, 255);
  GloveParser p(22);
  std::vector<GloveFrame> frames;
  Bytes chunk(4096);
  for (int i = 0; i < 256; ++i) {  // 1 MiB
    for (auto& b : chunk) b = static_cast<std::uint8_t>(byte(rng));
    frames.clear();
    p.feed(chunk.data(), chunk.size(), frames);
    ASSERT_LT(p.pending(), static_cast<std::size_t>(kMaxFrameBytes));
  }
  EXPECT_EQ(p.stats().bytes, 256u * 4096u);
  EXPECT_GT(p.stats().garbage_bytes, 256u * 4096u * 9 / 10);
  expectAccounted(p);
}

TEST(GloveProtocol, ResetWindowCountsPendingAsGarbage) {
  GloveParser p(22);
  const Bytes part = {'S', 1, 2, 3};
  p.feed(part.data(), part.size());
  EXPECT_EQ(p.pending(), 4u);
  p.resetWindow();
  EXPECT_EQ(p.pending(), 0u);
  EXPECT_EQ(p.stats().garbage_bytes, 4u);
  const Bytes rec = handRecord('S', 22, 5);
  EXPECT_EQ(p.feed(rec.data(), rec.size()).size(), 1u);
}

TEST(GloveProtocol, CommandParser) {
  CommandParser c;
  std::vector<GloveCommand> out;
  // "?X" is one unknown command, 'x' and 0 one each.
  const Bytes bytes = {'G', 'S', 0x03, '?', 'S', '?', 'X', 'x', 0};
  EXPECT_EQ(c.feed(bytes.data(), bytes.size(), out), 7u);
  const std::vector<GloveCommand> expected = {GloveCommand::kPoll,    GloveCommand::kStartStream,
                                              GloveCommand::kStopStream, GloveCommand::kQuerySensorCount,
                                              GloveCommand::kUnknown, GloveCommand::kUnknown,
                                              GloveCommand::kUnknown};
  EXPECT_EQ(out, expected);
  // A query split across two reads.
  out.clear();
  const std::uint8_t q = '?', s = 'S';
  EXPECT_EQ(c.feed(&q, 1, out), 0u);
  EXPECT_TRUE(c.pendingQuery());
  EXPECT_EQ(c.feed(&s, 1, out), 1u);
  EXPECT_EQ(out, std::vector<GloveCommand>{GloveCommand::kQuerySensorCount});
}
