// The haptic device as the servo loop sees it: read the HIP, write a force. Backends (the
// simulated replay in firmware/device_sim/, the Falcon over USB later) derive from HapticDevice;
// CMake and start-up code choose one, the loop never #ifdefs on it.
//
// Thread/RT rules: one thread (the servo thread) calls Read and Write, alternately, once per tick.
// RT-safe contract for every backend: DoRead/DoWrite must not allocate, lock, throw or block
// beyond the device transfer itself. Construction and destruction are non-RT.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>

namespace palpa::device {

/// Result of one device transfer.
enum class IoStatus {
  kOk,     ///< transfer done
  kError,  ///< transfer failed or returned invalid data; the loop writes zero force and stops
  kEnd,    ///< no more data (a replay ran out); not an error, the loop writes zero force and stops
};

/// One HIP sample. Device frame, the frame the blob's origin_m/voxel_m are expressed in.
struct HipReading {
  std::array<double, 3> hip_m{};  ///< haptic interface point, m
  double t_s = 0;                 ///< device time of the sample, s since the device started (replay time for a replay)
  std::uint8_t buttons = 0;       ///< button bitmask (Falcon grip: bits 0-3; a replay: the trace's column); 0 if none
};

/// NVI interface: the public non-virtual Read/Write check what crosses the boundary, the private
/// Do* do the transfer. Named for the capability, not "IDevice" (house style §7).
class HapticDevice {
 public:
  HapticDevice() = default;
  HapticDevice(const HapticDevice&) = delete;
  HapticDevice& operator=(const HapticDevice&) = delete;
  virtual ~HapticDevice() = default;

  /// Reads the current HIP into `out`. kOk with a non-finite HIP is reported as kError (a bad
  /// transfer must not reach the proxy). RT-safe per the backend contract above.
  IoStatus Read(HipReading& out) {
    const IoStatus s = DoRead(out);
    if (s == IoStatus::kOk && !(IsFinite(out.hip_m) && std::isfinite(out.t_s))) return IoStatus::kError;
    if (s == IoStatus::kOk) last_buttons_ = out.buttons;
    return s;
  }

  /// The buttons of the last successful Read (0 before any): what a button wired as an input (an
  /// e-stop or dead-man grip button, palpad --estop button:N) reads. Servo thread only.
  std::uint8_t last_buttons() const { return last_buttons_; }

  /// Commands `force_n` (N, device frame). A non-finite component is a programming error upstream:
  /// the device gets zero force instead and the call reports kError. RT-safe per the contract above.
  IoStatus Write(const std::array<double, 3>& force_n) {
    if (!IsFinite(force_n)) {
      (void)DoWrite({0.0, 0.0, 0.0});
      return IoStatus::kError;
    }
    return DoWrite(force_n);
  }

 private:
  static bool IsFinite(const std::array<double, 3>& v) {
    return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
  }

  virtual IoStatus DoRead(HipReading& out) = 0;
  virtual IoStatus DoWrite(const std::array<double, 3>& force_n) = 0;

  std::uint8_t last_buttons_ = 0;
};

}  // namespace palpa::device
