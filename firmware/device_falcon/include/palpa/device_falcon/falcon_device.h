// FalconDevice: the Novint Falcon as a HapticDevice — an explicit state machine over a
// FalconTransport (libusb or the virtual Falcon), the packet codec and the kinematics.
//
//   Unconfigured ─Configure()─▶ Inactive ─Home()─▶ Ready ─Activate()─▶ Active
//        │  (normal mode; firmware     (reading only;   (homed;      (force on:
//        │   found or uploaded)         LED red,         LED blue,    LED green)
//        │                              homing)          zero force)
//        └──────── any failure ─────────────────────────────────────▶ Fault (zero torque, LED red+blue)
//   Shutdown() from any state ─▶ Finalized (zero torque, LEDs off)
//
// One servo tick = DoWrite (send the command packet: forces from the latest position, like
// libnifalcon's runIOLoop) and the next DoRead (its 16-byte reply → encoders → FK → HIP). Every
// packet carries the homing bit ("must be set in each packet for the Falcon to stay homed").
// Safety (docs/falcon.md §4): torque is non-zero only in Active, i.e. after all three axes
// reported homed; a reply missing for more than 2 ms, a lost device, a USB error, an encoder jump
// beyond a physical bound, a lost homed flag, a failed forward kinematics or encoders that stay
// exactly still for stale_encoder_ns while torque is commanded (frozen firmware; its held torque first
// fades to zero over stale_ramp_ns) each latch Fault: the
// read reports kError, the loop writes zero force, which DoWrite turns into a zero-torque packet
// (best effort when the device is gone). FaultMessage() says what happened, for people.
//
// Thread/RT rules: Configure/Home/Activate/Shutdown/FaultMessage are non-RT (start-up thread).
// DoRead/DoWrite are RT-safe: no allocation, lock or exception; the only system calls are the
// transport's transfers and its clock.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <string>

#include "palpa/device/haptic_device.h"
#include "palpa/device/limits.h"
#include "palpa/device_falcon/firmware_loader.h"
#include "palpa/device_falcon/transport.h"
#include "palpa/falcon/codec.h"
#include "palpa/falcon/kinematics.h"

namespace palpa::device_falcon {

/// The Falcon's limits: CHAI3D's device specification for it (cFalconDevice's constructor,
/// src/devices/CFalconDevice.cpp: m_maxForceStiffness = 3000 N/m, m_maxForce = 8 N). Above
/// 3000 N/m a 1 kHz loop on the Falcon's arms goes unstable (buzz, then limit cycles); above 8 N
/// the amplifiers saturate (docs/falcon.md §4: commands beyond ±4095 counts are scaled down).
inline constexpr device::DeviceLimits kFalconLimits = {"the Novint Falcon", 3000.0, 8.0,
                                                       "CHAI3D's Falcon specification, cFalconDevice: 3000 N/m, 8 N"};

enum class FalconState { kUnconfigured, kInactive, kReady, kActive, kFault, kFinalized };
const char* FalconStateName(FalconState s);

/// LED colours per state (docs/falcon.md §4): what the device is doing, seen on the device.
inline constexpr std::uint8_t kLedHoming = falcon::kLedRed;                    ///< move out, then push in
inline constexpr std::uint8_t kLedReady = falcon::kLedBlue;                    ///< homed, no force yet
inline constexpr std::uint8_t kLedActive = falcon::kLedGreen;                  ///< forces on
inline constexpr std::uint8_t kLedFault = falcon::kLedRed | falcon::kLedBlue;  ///< stopped by a fault

enum class FalconFault {
  kNone,
  kReplyTimeout,    ///< no valid reply within reply_timeout_ns of the command
  kDisconnected,    ///< transport reported kNoDevice
  kUsbError,        ///< transport reported kIoError (or a short write)
  kEncoderJump,     ///< an encoder moved more than the physical bound since the last reply
  kLostHoming,      ///< a homed flag dropped while active
  kKinematics,      ///< forward kinematics found no pose for the encoders
  kEncodersFrozen,  ///< homing: replies came but no encoder ever changed
  kEncodersStale,   ///< active: no encoder changed for stale_encoder_ns while non-zero torque was commanded
  kHomingTimeout,   ///< homing: encoders moved but the three homed flags (or the pull-out) never came
  kNotActive,       ///< Read before Activate (programming error)
};

/// Details of the latched fault (plain data: the RT side fills it, FaultMessage formats it).
struct FaultInfo {
  FalconFault code = FalconFault::kNone;
  UsbStatus usb = UsbStatus::kOk;
  FalconState state = FalconState::kUnconfigured;  ///< state the fault happened in
  int axis = 0;                                    ///< 1..3 for jumps and homing flags
  std::int32_t jump_counts = 0;
  std::int32_t bound_counts = 0;
  std::int64_t waited_ns = 0;  ///< reply timeout: time since the command was sent
  std::int64_t at_ns = 0;      ///< transport clock when it happened
  std::uint64_t exchange = 0;  ///< command/reply pairs completed before it
  std::array<std::int16_t, 3> encoders{};
  std::uint8_t homed = 0;
  int fk_error = 0;
  std::array<std::int16_t, 3> command{};  ///< stale encoders: the motor command (counts) held meanwhile
  std::array<double, 3> force_n{};        ///< stale encoders: the force (N, device frame) asked for last
};

/// Counters the servo thread writes (house style §5).
struct FalconCounters {
  std::uint64_t exchanges = 0;              ///< command/reply pairs completed
  std::uint64_t discarded_bytes = 0;        ///< bytes skipped re-framing (garbage, cut frames)
  std::uint64_t status_only_transfers = 0;  ///< IN transfers that carried only FTDI status bytes
  std::uint64_t split_replies = 0;          ///< replies that took more than one IN transfer
  std::uint64_t saturated_commands = 0;     ///< commands scaled down to ±4095 counts
  std::uint64_t singular_poses = 0;         ///< force dropped because the Jacobian was singular
  std::int64_t max_reply_ns = 0;            ///< longest command→reply time
  int max_fk_iterations = 0;                ///< most Newton iterations in one forward kinematics
  std::uint64_t fk_iterations = 0;          ///< total Newton iterations
};

struct FalconConfig {
  /// Kinematic-frame point that is the device frame's origin: HIP = grip − origin. The fields
  /// palpa builds are centred at the device-frame origin (palpa build --fit); z 0.125 m is the
  /// middle of the grip's z range 0.075…0.175 m (libnifalcon colour test, VRPN).
  falcon::Vec3 workspace_origin_m = {0.0, 0.0, 0.125};
  std::int64_t reply_timeout_ns = 2'000'000;  ///< issue #8: replies missing > 2 ms stop the run
  /// Physical bound for encoder jumps: no hand turns an arm faster than this (60 rad/s ≈ 3.6 m/s
  /// at the grip); bound = speed × time since the last reply + slack counts.
  double max_joint_speed_rad_s = 60.0;
  std::int32_t jump_slack_counts = 8;
  /// After homing, forces are enabled only once the grip was pulled out beyond this z, m
  /// (libnifalcon's test scenes and VRPN wait for z > 0.170): the HIP then starts outside any
  /// object palpa centres at the workspace origin, so the proxy starts outside too.
  double activate_above_z_m = 0.170;
  /// Device supervision in contact (docs/falcon.md §5): the encoders of a Falcon under torque are
  /// never exactly still (±1 count of noise, hand tremor of several counts), so all three encoders
  /// reading exactly the same while every command of this long carried non-zero torque means the
  /// firmware stopped updating them (frozen@N); 0: off. Measured on the transport clock.
  std::int64_t stale_encoder_ns = 500'000'000;
  /// Once the encoders are found stale, the motor command held at that moment fades linearly to
  /// zero over this long before the fault latches (issue 18: a fault ramps to zero rather than
  /// dropping up to 8 N from under a hand that leans on it). The pose is unknown meanwhile, so no
  /// new force is computed: the loop's force is ignored and only the held torque shrinks. 0: step.
  std::int64_t stale_ramp_ns = 50'000'000;
  std::uint64_t tick_limit = 0;  ///< Read answers kEnd after this many ticks (0: never; a replay sets it)
  falcon::FkConfig fk;
};

enum class ConfigureResult {
  kOk,            ///< firmware runs (found or uploaded); state Inactive
  kNoFirmware,    ///< the DSP is in its boot ROM and no firmware file was given
  kLoadFailed,    ///< upload failed (message lists every attempt)
  kDisconnected,  ///< device gone
  kUsbError,
};

enum class HomeResult { kHomed, kTimeout, kFrozen, kStopped, kFault };

class FalconDevice final : public device::HapticDevice {
 public:
  /// `transport` must outlive the device. Non-RT.
  FalconDevice(FalconTransport& transport, const FalconConfig& config = {});
  /// Shutdown() if not done: zero torque, LEDs off.
  ~FalconDevice() override;

  /// Unconfigured → Inactive: normal mode, then ProbeFirmware; if silent and `firmware` is given,
  /// LoadFirmware. `log` gets one line per step ("firmware already loaded", the load report).
  ConfigureResult Configure(const FirmwareImage* firmware, const LoaderConfig& loader, std::string& log);

  /// Inactive → Ready: exchanges packets with the homing bit and the red LED (zero torque) until
  /// all three homed flags are set, then (blue LED) until the grip is pulled out beyond
  /// activate_above_z_m — or until `stop` is set or `timeout_s` passes on the transport clock.
  /// kFrozen: replies came but no encoder changed (either nobody moved the grip, or the firmware
  /// runs with frozen encoders — a known failure after a bad load); kTimeout: encoders moved but
  /// homing did not complete. Both latch Fault. Pacing: back to back (the device's round trip).
  HomeResult Home(const std::atomic<bool>& stop, double timeout_s);

  /// Ready → Active (forces on, green LED). False in any other state.
  bool Activate();

  /// Any state → Finalized: sends zero torque with the LEDs off (best effort) and drains the
  /// reply. Idempotent. Non-RT.
  void Shutdown();

  /// From a fatal-signal handler (palpad's crash path): one zero-torque packet with the fault
  /// LEDs, no reply read, no state change. Allocation-free; async-signal-safe only as far as the
  /// transport is (the virtual Falcon is; libusb is not: palpad bounds the call with alarm(2)).
  /// True if the transport took the whole packet.
  bool EmergencyZero() noexcept;

  FalconState state() const { return state_; }
  const FaultInfo& fault() const { return fault_; }
  /// The fault for people, one or two sentences; empty without a fault. Non-RT.
  std::string FaultMessage() const;
  const FalconCounters& counters() const { return counters_; }
  /// Last decoded status packet (encoders, buttons, homed flags).
  const falcon::DeviceStatus& last_status() const { return status_; }
  /// Grip position in the kinematic frame, m (valid once homed).
  const falcon::Vec3& grip_m() const { return grip_m_; }
  /// Last command packet sent (or attempted).
  const falcon::MotorCommand& last_command() const { return command_; }

 private:
  device::IoStatus DoRead(device::HipReading& out) override;
  device::IoStatus DoWrite(const std::array<double, 3>& force_n) override;

  bool Send(const falcon::MotorCommand& command);
  bool Receive(falcon::DeviceStatus& status);
  bool UpdatePose(const falcon::DeviceStatus& status, std::int64_t reply_ns);
  void Latch(FaultInfo info);
  void LatchUsb(UsbStatus s);
  device::IoStatus WriteZeroAfterFault();
  bool CheckEncodersMove(const std::array<std::int16_t, 3>& before, const std::array<std::int16_t, 3>& now_counts,
                         std::int64_t now_ns);

  FalconTransport& transport_;
  FalconConfig config_;
  FalconState state_ = FalconState::kUnconfigured;
  FaultInfo fault_;
  FalconCounters counters_;
  falcon::FrameReader reader_{falcon::FrameKind::kStatus};
  falcon::MotorCommand command_;
  falcon::DeviceStatus status_;
  bool outstanding_ = false;  // a command was sent whose reply has not been read
  std::int64_t sent_ns_ = 0;
  std::int64_t last_reply_ns_ = 0;
  std::int64_t active_start_ns_ = 0;
  std::uint64_t ticks_ = 0;
  falcon::Vec3 grip_m_ = {0.0, 0.0, 0.12};
  falcon::Mat3 jacobian_{};
  bool jacobian_ok_ = false;
  bool zero_sent_after_fault_ = false;
  std::int64_t still_since_ns_ = 0;                // encoders unchanged, torque non-zero, since then
  std::int64_t stale_ramp_start_ns_ = -1;          // ≥ 0: stale encoders found, the held torque is fading
  std::array<std::int16_t, 3> stale_ramp_from_{};  // the command held when they were found
  FaultInfo stale_fault_;                          // latched when the fade ends
  std::array<double, 3> last_force_n_{};           // the force DoWrite was asked for last
};

}  // namespace palpa::device_falcon
