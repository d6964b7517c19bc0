// PolicyExchange: activation times, a due policy before a newer one, the newest of several,
// and a writer and a reader on two threads: never a torn read, never an older policy after a
// newer one, never a policy before its time.
#include <adroit_mpc/policy_exchange.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <limits>
#include <thread>
#include <vector>

using Exchange = adroit_mpc::PolicyExchange<std::vector<std::uint64_t>>;

namespace {

constexpr double kNever = std::numeric_limits<double>::infinity();

// Fills the writer's slot with `value` and publishes it (serial = the number of publications).
void publish(Exchange& x, std::uint64_t value, double activation) {
  x.back().assign(4, value);
  x.publish(activation);
}

}  // namespace

TEST(PolicyExchange, NothingBeforeTheFirstPublication) {
  Exchange x;
  EXPECT_FALSE(x.update(kNever));
  EXPECT_FALSE(x.hasActive());
  EXPECT_FALSE(x.hasPending());
}

TEST(PolicyExchange, AtOnceTakesOverOnTheNextUpdate) {
  Exchange x;
  publish(x, 7, Exchange::kAtOnce);
  EXPECT_TRUE(x.update(-1e9));
  ASSERT_TRUE(x.hasActive());
  EXPECT_EQ(x.active().serial, 1u);
  EXPECT_EQ(x.active().policy[0], 7u);
  EXPECT_FALSE(x.update(-1e9));  // nothing newer
}

TEST(PolicyExchange, APolicyWaitsForItsActivationTime) {
  Exchange x;
  publish(x, 1, Exchange::kAtOnce);
  x.update(0);
  publish(x, 2, 1.05);
  EXPECT_FALSE(x.update(1.0499));
  EXPECT_TRUE(x.hasPending());
  EXPECT_DOUBLE_EQ(x.pendingActivation(), 1.05);
  EXPECT_EQ(x.active().policy[0], 1u);  // the running one is acted on meanwhile
  EXPECT_TRUE(x.update(1.05));
  EXPECT_EQ(x.active().policy[0], 2u);
  EXPECT_DOUBLE_EQ(x.active().activation, 1.05);
  EXPECT_FALSE(x.hasPending());
}

TEST(PolicyExchange, ADuePolicyRunsBeforeANewerOneReplacesIt) {
  Exchange x;
  publish(x, 1, 1.0);
  EXPECT_FALSE(x.update(0.5));  // pending
  publish(x, 2, 2.0);
  // At 1.0 the first is due: it becomes active, and the second waits for 2.0.
  EXPECT_TRUE(x.update(1.0));
  EXPECT_EQ(x.active().policy[0], 1u);
  EXPECT_TRUE(x.hasPending());
  EXPECT_TRUE(x.update(2.0));
  EXPECT_EQ(x.active().policy[0], 2u);
}

TEST(PolicyExchange, AReaderThatMissedPublicationsGetsTheNewest) {
  Exchange x;
  for (std::uint64_t v = 1; v <= 5; ++v) publish(x, v, Exchange::kAtOnce);
  EXPECT_TRUE(x.update(0));
  EXPECT_EQ(x.active().serial, 5u);
  EXPECT_EQ(x.active().policy[0], 5u);
}

// Slot ownership: while the reader acts on one policy and holds newer ones pending, the writer
// goes on writing its slots; none of them is the active one.
TEST(PolicyExchange, TheActivePolicyIsNeverWrittenWhileTheWriterGoesOn) {
  Exchange x;
  publish(x, 1, Exchange::kAtOnce);
  x.update(0);
  for (std::uint64_t v = 2; v < 50; ++v) {
    publish(x, v, kNever);  // never due
    EXPECT_FALSE(x.update(1e9));
    EXPECT_TRUE(x.hasPending());
    ASSERT_EQ(x.active().policy, std::vector<std::uint64_t>(4, 1u)) << "after policy " << v;
    x.back().assign(4, 1000 + v);  // the writer starts on the next one
    ASSERT_EQ(x.active().policy, std::vector<std::uint64_t>(4, 1u)) << "after policy " << v;
  }
  EXPECT_EQ(x.active().serial, 1u);
}

// The writer publishes policies 1..N, each filled twice (zeros, then its number: a reader of a
// slot being written would see zeros or a mix), policy v due at time v on the reader's clock.
// Most are published a quarter of a time unit before their time and wait pending for it;
// every third 1.75 units before, so it replaces one that is still pending while the reader acts
// on an older one (the writer goes on writing while a policy waits). The reader's clock counts
// its updates, 8 per time unit, and waits for the writer when it gets ahead.
TEST(PolicyExchange, ConcurrentWriterAndReaderNeverTearNorGoBackNorRunEarly) {
  constexpr std::uint64_t kPolicies = 6000;
  constexpr std::size_t kSize = 512;
  constexpr double kUpdatesPerUnit = 8;
  Exchange x;
  x.forEachPolicy([](std::vector<std::uint64_t>& p) { p.assign(kSize, 0); });
  std::atomic<std::uint64_t> clock{0}, written{0};  // the reader's update count, the writer's newest
  std::thread writer([&] {
    for (std::uint64_t v = 1; v <= kPolicies; ++v) {
      const double lead = v % 3 == 0 ? 1.75 : 0.25;
      while (clock.load() / kUpdatesPerUnit < v - lead) std::this_thread::yield();
      std::vector<std::uint64_t>& p = x.back();
      for (auto& e : p) e = 0;
      for (auto& e : p) e = v;
      x.publish(static_cast<double>(v));
      written.store(v);
    }
  });
  std::uint64_t last = 0, changes = 0, waited = 0, torn = 0, early = 0, backwards = 0;
  for (std::uint64_t n = 0, loops = 0; last < kPolicies && loops < 500000000; ++loops) {
    const double now = n / kUpdatesPerUnit;
    changes += x.update(now);
    waited += x.hasPending();
    if (x.hasActive()) {
      const Exchange::Slot& s = x.active();
      for (std::uint64_t e : s.policy) torn += e != s.serial;
      early += !(s.activation <= now);
      backwards += s.serial < last;
      last = s.serial;
    }
    if (now < written.load() + 0.875) clock.store(++n);
    else std::this_thread::yield();
  }
  writer.join();
  EXPECT_EQ(torn, 0u);
  EXPECT_EQ(early, 0u);
  EXPECT_EQ(backwards, 0u);
  EXPECT_EQ(last, kPolicies);  // the last one arrives
  // Each policy was acted on in turn, but for some of those replaced by an early publication
  // (how many depends on how promptly the writer ran).
  EXPECT_LE(changes, kPolicies);
  EXPECT_GE(changes, kPolicies - kPolicies / 3);
  EXPECT_GT(waited, kPolicies);  // they waited for their time
}
