// `palpad --swap-at N:FIELD`: a field swap at a known tick, for replays (HIL's swap-mid-contact
// case) where an upload over TCP would land on whichever tick the network allows. A decorator of
// the device: during tick N's read it offers FIELD to the loop through the same wait-free
// ServoLoop::OfferField an upload uses; the loop takes offers right after its read, so tick N
// runs on FIELD, with the same swap, proxy re-seed and force cross-fade (docs/upload.md). FIELD is read and verified
// at start-up, like the start-up field. RT-safe: one counter and, once, one atomic exchange.
#pragma once

#include <array>
#include <cstdint>

#include "palpa/device/haptic_device.h"
#include "palpa/servo/servo_loop.h"

namespace palpa::palpad {

class ScriptedSwapDevice final : public device::HapticDevice {
 public:
  /// Offers `field` during the read of tick `tick` (0-based) of `inner`. Both must outlive this.
  ScriptedSwapDevice(device::HapticDevice& inner, const servo::ServoField& field, std::uint64_t tick)
      : inner_(inner), field_(field), tick_(tick) {}
  /// The loop to offer to; set before it runs.
  void Attach(servo::ServoLoop& loop) { loop_ = &loop; }

 private:
  device::IoStatus DoRead(device::HipReading& out) override {
    const device::IoStatus s = inner_.Read(out);
    if (s == device::IoStatus::kOk && reads_++ == tick_ && loop_ != nullptr) (void)loop_->OfferField(&field_);
    return s;
  }
  device::IoStatus DoWrite(const std::array<double, 3>& force_n) override { return inner_.Write(force_n); }

  device::HapticDevice& inner_;
  const servo::ServoField& field_;
  std::uint64_t tick_;
  std::uint64_t reads_ = 0;
  servo::ServoLoop* loop_ = nullptr;
};

}  // namespace palpa::palpad
