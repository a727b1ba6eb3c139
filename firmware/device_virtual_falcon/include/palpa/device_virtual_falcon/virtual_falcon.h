// VirtualFalcon: a simulated Novint Falcon behind the FalconTransport interface. It consumes and
// produces the same bytes as the real one — FTDI vendor requests, the boot-ROM handshake and the
// echoed firmware upload, 16-byte command packets in, 16-byte status packets out with 2 FTDI
// status bytes per IN transfer — so the codec, the firmware loader and FalconDevice run
// unchanged on it.
//
// Model (docs/falcon.md "Virtual Falcon"):
//  - Clock: simulated, ns. A runtime command arrives no earlier than one period (1/rate_hz) after
//    the previous one (the host's servo pacing); the reply is ready 0.2 ms later plus the FTDI
//    latency timer beyond 1 ms; an IN transfer with nothing to send returns the 2 status bytes
//    after one latency period. Timeouts therefore happen in simulated time, deterministically.
//  - Mechanics: the Falcon's kinematics (palpa/falcon/kinematics.h) and encoder resolution; the
//    grip is a point mass pulled by a hand (mass-spring-damper towards a target) and pushed by
//    the motors (F = Jᵀ·τ, τ = −counts/10000 N·m, each motor clamped at ±4096 counts: torque
//    saturation). A pose outside the reachable set is a mechanical stop.
//  - The hand follows the LEDs like a user: red → the homing gesture (all the way out, then in);
//    blue → pulls the grip out (z 0.174 m, above any object) so that the host enables forces;
//    green → the HIP trace (device frame + workspace origin), blended in from there over 0.5 s.
//  - Firmware: power-up in the boot ROM (firmware_loaded = false) or with firmware running.
//    Homing: an axis is homed once its arm went beyond 55° and came back through 35° with the
//    homing bit set; its encoder zero then moves to θ1 = 35°. A packet without the homing bit
//    clears the homed flags.
//  - Faults (FaultSpec), each tied to a runtime exchange index or an upload byte offset.
//
// RT-safe transfers (fixed buffers, no allocation). Construction is non-RT. One thread.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <string>
#include <string_view>
#include <vector>

#include "palpa/device_falcon/transport.h"
#include "palpa/falcon/codec.h"
#include "palpa/falcon/kinematics.h"
#include "palpa/trace/trace.h"

namespace palpa::device_virtual_falcon {

enum class FaultKind {
  kDrop,      ///< drop@N: no reply from exchange N on
  kSplit,     ///< split@N: from exchange N on, each reply comes in two IN transfers (split point varies)
  kGarbage,   ///< garbage@N: junk bytes (a stray '<', a cut frame) before the reply of exchange N
  kCorrupt,   ///< corrupt@N: the reply of exchange N loses its '>' (no valid frame)
  kUnplug,    ///< unplug@N: every transfer from exchange N on fails with "no device"
  kFrozen,    ///< frozen@N: encoders and homed flags stop changing from exchange N on
  kJump,      ///< jump@N: encoder 2 reads 3000 counts off from exchange N on
  kEcho,      ///< echo@B: the upload echo of byte B is wrong on every attempt
  kEchoOnce,  ///< echo-once@B: the same, on the first attempt only
};

struct FaultSpec {
  FaultKind kind = FaultKind::kDrop;
  std::uint64_t at = 0;  ///< exchange index (0-based, runtime packets) or upload byte offset
};

/// Parses a comma-separated fault list, e.g. "split@0,unplug@1500" ("frozen" = "frozen@0").
/// Error: one sentence naming the bad item.
std::expected<std::vector<FaultSpec>, std::string> ParseFaults(std::string_view text);

/// The hand holding the grip: a mass-spring-damper pulled towards the target.
struct HandModel {
  double mass_kg = 0.15;           ///< grip, arms and hand, moved together
  double stiffness_n_per_m = 400;  ///< arm stiffness (human arm: a few hundred N/m)
  double damping_n_s_per_m = 15;   ///< ≈ critical for the values above
};

struct VirtualFalconConfig {
  double rate_hz = 1000;                  ///< host command rate the clock models
  bool firmware_loaded = true;            ///< false: power-up in the boot ROM
  std::vector<trace::TraceSample> trace;  ///< HIP trace, device frame (empty: the hand holds still)
  falcon::Vec3 workspace_origin_m = {0.0, 0.0, 0.125};
  falcon::Vec3 power_up_grip_m = {0.0, 0.0, 0.11};
  HandModel hand;
  std::vector<FaultSpec> faults;
};

/// One LED change as the device saw it.
struct LedChange {
  std::int64_t t_ns = 0;
  std::uint8_t leds = 0;   ///< kLed* bits
  std::uint8_t homed = 0;  ///< homed flags at that moment
};

class VirtualFalcon final : public device_falcon::FalconTransport {
 public:
  explicit VirtualFalcon(VirtualFalconConfig config);

  // ---- inspection (tests, palpad's summary); not part of the wire ----
  bool firmware_running() const { return dsp_ == Dsp::kRunning; }
  const falcon::Vec3& grip_m() const { return p_; }
  /// Force the motors apply to the grip now, N.
  const falcon::Vec3& motor_force_n() const { return motor_force_n_; }
  /// Last command packet decoded (what the motors do now).
  const falcon::MotorCommand& last_command() const { return command_; }
  std::uint64_t commands() const { return commands_; }
  std::uint64_t replies() const { return replies_; }
  /// Commands with non-zero counts received while not all three axes were homed (must stay 0).
  std::uint64_t torque_before_homed() const { return torque_before_homed_; }
  /// Runtime packets answered since the first green-LED packet (fault indices count these).
  std::uint64_t run_exchanges() const { return run_exchanges_; }
  /// Motor commands beyond ±4096 that the amplifier clamped.
  std::uint64_t amplifier_clamps() const { return amplifier_clamps_; }
  std::uint64_t uploads_completed() const { return uploads_completed_; }
  std::uint8_t homed() const { return homed_; }
  const std::array<std::int16_t, 3>& encoders() const { return encoders_; }
  /// LED changes in order (the first 64).
  std::span<const LedChange> led_changes() const { return {leds_log_.data(), leds_log_count_}; }
  /// Zero-torque state: the last command has zero counts.
  bool torque_is_zero() const { return command_.counts == std::array<std::int16_t, 3>{}; }

 private:
  enum class Dsp { kBootRom, kAwaitAutobaud, kStream, kRunning };
  enum class Hand { kRest, kHoming, kPullOut, kTrace };

  device_falcon::UsbStatus DoControlOut(std::uint8_t request, std::uint16_t value, int timeout_ms) override;
  device_falcon::UsbStatus DoBulkOut(std::span<const std::uint8_t> bytes, std::size_t& written,
                                     std::int64_t timeout_us) override;
  device_falcon::UsbStatus DoBulkIn(std::span<std::uint8_t> buf, std::size_t& got, std::int64_t timeout_us) override;
  std::int64_t DoNowNs() override { return now_ns_; }

  bool Unplugged() const;
  bool FaultAt(FaultKind kind, std::uint64_t at_most) const;
  void Queue(std::int64_t avail_ns, std::span<const std::uint8_t> bytes);
  void BootByte(std::uint8_t b);
  void Exchange(const falcon::MotorCommand& cmd);
  void Integrate(std::int64_t to_ns);
  falcon::Vec3 HandTarget(std::int64_t t_ns) const;
  void UpdateEncoders();
  std::int64_t ReplyDelayNs() const;

  VirtualFalconConfig config_;
  std::int64_t period_ns_;
  std::int64_t now_ns_ = 0;

  // FTDI side
  std::uint16_t baud_ = 0x4138;
  std::uint16_t latency_ms_ = 16;
  bool dtr_ = false;
  struct Segment {
    std::int64_t avail_ns = 0;
    std::uint8_t len = 0;
    std::array<std::uint8_t, 62> bytes{};
  };
  static constexpr std::size_t kSegments = 32;
  std::array<Segment, kSegments> segments_{};
  std::size_t seg_head_ = 0, seg_count_ = 0;
  falcon::FrameReader commands_in_{falcon::FrameKind::kCommand};

  // DSP side
  Dsp dsp_;
  std::array<std::uint8_t, 3> handshake_{};  // last 3 bytes seen by the boot ROM
  // Boot stream parser (TI 8-bit boot format), word by word: the ROM knows where the stream ends.
  std::uint64_t stream_bytes_ = 0;  // boot stream bytes received this attempt
  std::uint64_t words_left_ = 0;    // words left in the header or the current block
  bool expect_block_size_ = false;
  bool have_low_byte_ = false;
  std::uint8_t low_byte_ = 0;
  std::uint64_t upload_attempts_ = 0;
  std::uint64_t uploads_completed_ = 0;
  std::array<std::uint8_t, 64> echo_buf_{};  // echoes of one bulk OUT (≤ 62 bytes)
  std::size_t echo_len_ = 0;

  // Runtime
  std::uint64_t firmware_exchanges_ = 0;  // command packets the firmware answered (frozen@N counts these)
  bool run_started_ = false;              // a green-LED (force-on) packet arrived
  std::uint64_t run_exchanges_ = 0;       // packets since then (the other faults' N counts these)
  std::int64_t last_cmd_ns_ = -1;
  falcon::MotorCommand command_;
  std::uint64_t commands_ = 0, replies_ = 0, torque_before_homed_ = 0, amplifier_clamps_ = 0;
  std::uint8_t homed_ = 0;
  std::array<bool, 3> axis_out_{};
  std::array<double, 3> encoder_zero_{};  // encoder count (real) that reads as 0
  std::array<std::int16_t, 3> encoders_{};
  std::uint8_t leds_ = 0;
  std::array<LedChange, 64> leds_log_{};
  std::size_t leds_log_count_ = 0;

  // Mechanics (kinematic frame)
  falcon::Vec3 p_, v_{}, motor_force_n_{};
  std::int64_t physics_ns_ = 0;
  bool physics_started_ = false;
  falcon::Vec3 hand_prev_{};  // hand target one substep ago (for its velocity)
  Hand hand_ = Hand::kRest;
  std::int64_t hand_phase_ns_ = 0;
  falcon::Vec3 hand_from_{};
  mutable std::size_t trace_cursor_ = 0;  // trace::HipAt's monotonic hint
};

}  // namespace palpa::device_virtual_falcon
