// A wait-free single-producer/single-consumer ring: the one way telemetry leaves the servo loop
// (house style §3b). The producer (the servo thread) never waits, locks, allocates or makes a
// system call; the consumer (a non-RT drain thread) polls.
//
// Thread rules: exactly one producer thread calls Push/TryPush, exactly one consumer thread calls
// Pop/ForEachQueued; capacity()/dropped()/pushed() may be read from any thread. Construction and
// destruction are non-RT (one allocation, every slot value-initialised, i.e. touched, so that the
// loop never page-faults on it).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <span>
#include <type_traits>

namespace palpa::rt {

/// What a full ring does with a new element. The policy is part of the ring's type, so a reader
/// of the declaration knows whether elements can be lost, and which ones.
enum class OnFull {
  /// The new element is dropped and counted (dropped()); everything already queued is kept, in
  /// order. The consumer sees a gap-free prefix and learns how much was lost.
  kDropNewest,
};

/// Lamport's SPSC queue with cached indices (each side re-reads the other's index only when its
/// cached copy says full/empty). Indices are 64-bit counters that never wrap in practice
/// (2^64 ticks at 10 kHz is 58 million years); slot = counter mod capacity, so any capacity ≥ 1
/// works and is exact.
///
/// Only kDropNewest exists: an overwriting SPSC ring must let the producer rewrite a slot the
/// consumer may be copying, which needs a per-slot seqlock; telemetry wants counted drops instead.
template <typename T, OnFull kPolicy>
class SpscRing {
  static_assert(std::is_trivially_copyable_v<T>, "only trivially copyable values may cross the RT boundary");
  static_assert(std::is_default_constructible_v<T>);
  static_assert(kPolicy == OnFull::kDropNewest, "only the drop-newest policy is implemented (see above)");
  static_assert(std::atomic<std::uint64_t>::is_always_lock_free, "the ring's indices must be lock-free");

 public:
  /// `capacity` ≥ 1 elements (0 is treated as 1). Non-RT: allocates and touches every slot.
  explicit SpscRing(std::size_t capacity)
      : capacity_(capacity == 0 ? 1 : capacity), slots_(std::make_unique<T[]>(capacity_)) {}

  SpscRing(const SpscRing&) = delete;
  SpscRing& operator=(const SpscRing&) = delete;

  /// Producer. Queues `v`; when full, drops it, counts it in dropped() and returns false.
  /// RT-safe: wait-free, no allocation, lock or system call.
  bool Push(const T& v) noexcept {
    if (TryPush(v)) return true;
    dropped_.store(dropped_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);  // one writer
    return false;
  }

  /// Producer. Queues `v` or returns false when full, counting nothing: for a caller that waits
  /// for room instead of losing data (lockstep replay; not RT). Wait-free itself.
  bool TryPush(const T& v) noexcept {
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_cache_ >= capacity_) {
      tail_cache_ = tail_.load(std::memory_order_acquire);
      if (head - tail_cache_ >= capacity_) return false;
    }
    slots_[Slot(head)] = v;
    head_.store(head + 1, std::memory_order_release);
    return true;
  }

  /// Consumer. Moves the oldest element into `out`; false when empty. Wait-free.
  bool Pop(T& out) noexcept {
    const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    if (tail == head_cache_) {
      head_cache_ = head_.load(std::memory_order_acquire);
      if (tail == head_cache_) return false;
    }
    out = slots_[Slot(tail)];
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  /// Consumer. Calls f(const T&) on every queued element, oldest first, without removing any.
  template <typename F>
  void ForEachQueued(F&& f) const {
    const std::uint64_t head = head_.load(std::memory_order_acquire);
    for (std::uint64_t i = tail_.load(std::memory_order_relaxed); i != head; ++i) f(slots_[Slot(i)]);
  }

  std::size_t capacity() const { return capacity_; }
  /// Elements queued now (exact on the producer's or consumer's thread when the other is idle).
  std::size_t size() const {
    return static_cast<std::size_t>(head_.load(std::memory_order_acquire) - tail_.load(std::memory_order_acquire));
  }
  /// Elements Push dropped because the ring was full.
  std::uint64_t dropped() const { return dropped_.load(std::memory_order_relaxed); }
  /// Elements queued since construction.
  std::uint64_t pushed() const { return head_.load(std::memory_order_relaxed); }
  /// The slot storage, for pre-faulting and memory locking.
  std::span<const std::byte> storage() const { return std::as_bytes(std::span<const T>(slots_.get(), capacity_)); }

 private:
  // The remainder is < capacity_, so it fits size_t also where size_t is 32-bit (armhf).
  std::size_t Slot(std::uint64_t counter) const { return static_cast<std::size_t>(counter % capacity_); }

  // 64 bytes: the cache line of every target palpa builds for (x86-64, Cortex-A53/A72, Cortex-A7).
  static constexpr std::size_t kLine = 64;

  const std::size_t capacity_;
  const std::unique_ptr<T[]> slots_;
  alignas(kLine) std::atomic<std::uint64_t> head_{0};  // written by the producer
  std::uint64_t tail_cache_ = 0;                       // producer's copy of tail_
  std::atomic<std::uint64_t> dropped_{0};              // written by the producer
  alignas(kLine) std::atomic<std::uint64_t> tail_{0};  // written by the consumer
  std::uint64_t head_cache_ = 0;                       // consumer's copy of head_
};

}  // namespace palpa::rt
