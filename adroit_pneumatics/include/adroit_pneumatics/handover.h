// Hand-over of the newest value from one thread to another without locks or allocation
// (a triple buffer). The pool's 200 Hz tick uses it in both directions: callbacks hand it
// validated references and states, the tick hands its commands to the publisher thread.
// Neither side ever waits for the other, so a slow or descheduled thread (a callback thread
// in the middle of a large message, a publisher serialising) cannot delay the tick.
#pragma once

#include <array>
#include <atomic>

namespace adroit::pneumatics {

// Single producer, single consumer, newest value wins: values the consumer did not take
// before the next publish() are overwritten (a newer one replaces them). The three
// buffers are allocated once; the producer fills back() in place (reusing its capacity),
// the consumer reads front() in place, and publish()/take() only exchange indices.
template <typename T>
class LatestValue {
 public:
  explicit LatestValue(const T& initial = T{}) : buffers_{initial, initial, initial} {}
  LatestValue(const LatestValue&) = delete;
  LatestValue& operator=(const LatestValue&) = delete;

  // Producer side: the buffer to fill, then publish() it.
  T& back() { return buffers_[back_]; }
  void publish() {
    // The filled buffer becomes the middle one (marked fresh); the old middle one, which
    // the consumer did not take, is the producer's next back buffer.
    back_ = middle_.exchange(back_ | kFresh, std::memory_order_acq_rel) & kIndex;
  }

  // Consumer side: true if a value newer than the last one taken was published; front()
  // is then that value, and stays the consumer's until the next successful take().
  bool take() {
    if (!(middle_.load(std::memory_order_acquire) & kFresh)) return false;
    front_ = middle_.exchange(front_, std::memory_order_acq_rel) & kIndex;
    return true;
  }
  T& front() { return buffers_[front_]; }
  const T& front() const { return buffers_[front_]; }

 private:
  static constexpr int kIndex = 3, kFresh = 4;
  std::array<T, 3> buffers_;
  int back_ = 0;                // producer's
  std::atomic<int> middle_{1};  // index of the shared buffer | kFresh when not yet taken
  int front_ = 2;               // consumer's
};

}  // namespace adroit::pneumatics
