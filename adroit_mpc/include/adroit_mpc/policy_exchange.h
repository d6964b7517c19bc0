// Hands policies from one writer thread (the MPC side: the planner) to one reader thread (the
// control side) without either ever waiting, and without allocating once each slot holds a
// policy of its final size.
//
// Four slots. The writer fills its back slot and publishes it by one atomic exchange with the
// shared middle slot; the reader takes the middle slot as its pending policy and makes that its
// active one once the reader's clock reaches the policy's activation time. A slot is touched
// only by the side that owns its index, so no read sees a half-written policy, and the active
// policy is never replaced by an older one. Three slots would do if every policy took over on
// publication (the node); the fourth lets the control side go on acting on the running policy
// while a published one waits for its time (emulated real time: mpc_success).
//
// A pending policy that a newer one replaces before its time has come is dropped. Activation
// times grow with publication (a plan takes over after the state it started from), so that
// only happens when the reader falls behind.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <limits>
#include <utility>

namespace adroit_mpc {

template <typename Policy>
class PolicyExchange {
 public:
  struct Slot {
    Policy policy;
    double activation = 0;     // the reader's time from which the policy is acted on
    std::uint64_t serial = 0;  // publication number: 1, 2, ... (0: never published)
  };
  static constexpr double kAtOnce = -std::numeric_limits<double>::infinity();

  // Set-up only, before either side runs (e.g. binding every slot's policy to a model).
  template <typename F>
  void forEachPolicy(F&& f) {
    for (Slot& s : slots_) f(s.policy);
  }

  // --- writer (one thread) ---
  Policy& back() { return slots_[back_].policy; }
  // The back slot becomes the newest published policy; the writer gets a free slot back.
  void publish(double activation = kAtOnce) {
    Slot& s = slots_[back_];
    s.activation = activation;
    s.serial = ++published_;
    back_ = middle_.exchange(back_ | kFresh) & kIndex;
  }
  std::uint64_t published() const { return published_; }

  // --- reader (one thread) ---
  // Takes the newest published policy and activates it once now >= its activation time.
  // True when the active policy changed. A reference from active() stays valid until the next
  // update().
  bool update(double now) {
    // A pending policy whose time has come runs before a newer one can replace it.
    const bool earlier = activateDue(now);
    if (middle_.load() & kFresh) {
      pending_ = middle_.exchange(pending_) & kIndex;  // the reader's free slot goes back
      has_pending_ = true;
    }
    return activateDue(now) || earlier;
  }
  bool hasActive() const { return has_active_; }
  const Slot& active() const { return slots_[active_]; }
  bool hasPending() const { return has_pending_; }
  double pendingActivation() const { return slots_[pending_].activation; }

 private:
  bool activateDue(double now) {
    if (!has_pending_ || !(slots_[pending_].activation <= now)) return false;
    std::swap(active_, pending_);  // the old active slot is the reader's free one now
    has_pending_ = false;
    has_active_ = true;
    return true;
  }

  static constexpr int kIndex = 3, kFresh = 4;
  std::array<Slot, 4> slots_;
  int back_ = 0;                                   // the writer's
  int active_ = 1, pending_ = 2;                   // the reader's
  std::atomic<int> middle_{3};                     // shared: index | kFresh when unread
  std::uint64_t published_ = 0;                    // the writer's
  bool has_active_ = false, has_pending_ = false;  // the reader's
};

}  // namespace adroit_mpc
