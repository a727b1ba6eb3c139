#include "palpa/device_falcon/falcon_device.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>

#include "palpa/device_falcon/ftdi.h"

namespace palpa::device_falcon {
namespace {

using falcon::DeviceStatus;
using falcon::MotorCommand;

// A late servo thread must not turn a reply that is already waiting in the FTDI into a "missing
// reply": when the read starts after the deadline, it still gets one latency period to arrive.
constexpr std::int64_t kLateReadGraceNs = 1'000'000;
// Transfers per reply: the FTDI sends a status-only packet per latency period (1 ms), so a
// 2 ms deadline needs a handful; the cap bounds the loop whatever the transport does.
constexpr int kMaxTransfersPerReply = 64;

constexpr double kCountsPerRad = 180.0 / (std::numbers::pi * falcon::kEncoderDegPerCount);

std::string Encoders(const std::array<std::int16_t, 3>& e) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "(%d, %d, %d)", e[0], e[1], e[2]);
  return buf;
}

std::string Ms(std::int64_t ns) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3f ms", static_cast<double>(ns) / 1e6);
  return buf;
}

}  // namespace

const char* FalconStateName(FalconState s) {
  switch (s) {
    case FalconState::kUnconfigured:
      return "unconfigured";
    case FalconState::kInactive:
      return "inactive (not homed)";
    case FalconState::kReady:
      return "ready (homed, no force)";
    case FalconState::kActive:
      return "active (force on)";
    case FalconState::kFault:
      return "fault";
    case FalconState::kFinalized:
      return "finalized";
  }
  return "?";
}

FalconDevice::FalconDevice(FalconTransport& transport, const FalconConfig& config)
    : transport_(transport), config_(config) {}

FalconDevice::~FalconDevice() { Shutdown(); }

void FalconDevice::Latch(FaultInfo info) {
  if (state_ == FalconState::kFault || state_ == FalconState::kFinalized) return;  // the first fault wins
  info.state = state_;
  info.at_ns = transport_.NowNs();
  info.exchange = counters_.exchanges;
  if (info.encoders == std::array<std::int16_t, 3>{}) info.encoders = status_.encoders;
  fault_ = info;
  state_ = FalconState::kFault;
}

void FalconDevice::LatchUsb(UsbStatus s) {
  FaultInfo f;
  f.code = s == UsbStatus::kNoDevice ? FalconFault::kDisconnected : FalconFault::kUsbError;
  f.usb = s;
  Latch(f);
}

bool FalconDevice::Send(const MotorCommand& command) {
  command_ = command;
  const falcon::Packet p = falcon::EncodeCommand(command);
  std::size_t written = 0;
  const UsbStatus s = transport_.BulkOut(p, written, config_.reply_timeout_ns / 1000);
  if (s != UsbStatus::kOk || written != p.size()) {
    LatchUsb(s == UsbStatus::kOk || s == UsbStatus::kTimeout ? UsbStatus::kIoError : s);
    return false;
  }
  sent_ns_ = transport_.NowNs();
  outstanding_ = true;
  return true;
}

bool FalconDevice::Receive(DeviceStatus& status) {
  const std::int64_t start_ns = transport_.NowNs();
  const std::int64_t deadline = std::max(sent_ns_ + config_.reply_timeout_ns, start_ns + kLateReadGraceNs);
  int payload_transfers = 0;
  for (int transfers = 0;; ++transfers) {
    falcon::Packet p{};
    if (reader_.Next(p)) {
      const std::int64_t now = transport_.NowNs();
      status = *falcon::DecodeStatus(p);  // Next() only hands out valid status frames
      outstanding_ = false;
      counters_.discarded_bytes = reader_.discarded_bytes();
      if (payload_transfers > 1) ++counters_.split_replies;
      counters_.max_reply_ns = std::max(counters_.max_reply_ns, now - sent_ns_);
      ++counters_.exchanges;
      return true;
    }
    const std::int64_t now = transport_.NowNs();
    if (now >= deadline || transfers >= kMaxTransfersPerReply) {
      FaultInfo f;
      f.code = FalconFault::kReplyTimeout;
      f.waited_ns = now - sent_ns_;
      counters_.discarded_bytes = reader_.discarded_bytes();
      Latch(f);
      return false;
    }
    std::array<std::uint8_t, kBulkInBytes> raw{};
    std::size_t got = 0;
    const std::int64_t left_us = (deadline - now + 999) / 1000;
    const UsbStatus s = transport_.BulkIn(raw, got, left_us);
    if (s == UsbStatus::kNoDevice || s == UsbStatus::kIoError) {
      LatchUsb(s);
      return false;
    }
    if (got <= falcon::kFtdiStatusBytes) {
      ++counters_.status_only_transfers;
    } else {
      ++payload_transfers;
    }
    reader_.PushUsbTransfer(std::span<const std::uint8_t>(raw.data(), got));
  }
}

bool FalconDevice::UpdatePose(const DeviceStatus& st, std::int64_t reply_ns) {
  if (!st.AllHomed()) {
    FaultInfo f;
    f.code = FalconFault::kLostHoming;
    f.homed = st.homed;
    f.encoders = st.encoders;
    for (int a = 0; a < 3; ++a)
      if ((st.homed & (1 << a)) == 0) {
        f.axis = a + 1;
        break;
      }
    Latch(f);
    return false;
  }
  const double dt_s = static_cast<double>(std::max<std::int64_t>(0, reply_ns - last_reply_ns_)) * 1e-9;
  const auto bound =
      static_cast<std::int32_t>(config_.max_joint_speed_rad_s * dt_s * kCountsPerRad) + config_.jump_slack_counts;
  for (std::size_t a = 0; a < 3; ++a) {
    const std::int32_t jump = std::int32_t{st.encoders[a]} - std::int32_t{status_.encoders[a]};
    if (std::abs(jump) > bound) {
      FaultInfo f;
      f.code = FalconFault::kEncoderJump;
      f.axis = static_cast<int>(a) + 1;
      f.jump_counts = jump;
      f.bound_counts = bound;
      f.waited_ns = reply_ns - last_reply_ns_;
      f.encoders = st.encoders;
      Latch(f);
      return false;
    }
  }
  const falcon::FkOutcome fk = falcon::ForwardKinematics(falcon::EncodersToTheta(st.encoders), grip_m_, config_.fk);
  counters_.fk_iterations += static_cast<std::uint64_t>(fk.iterations);
  counters_.max_fk_iterations = std::max(counters_.max_fk_iterations, fk.iterations);
  if (!fk.result) {
    FaultInfo f;
    f.code = FalconFault::kKinematics;
    f.fk_error = static_cast<int>(fk.error);
    f.encoders = st.encoders;
    Latch(f);
    return false;
  }
  grip_m_ = fk.result->p_m;
  const auto legs = falcon::InverseKinematics(grip_m_);
  jacobian_ok_ = legs.has_value();
  if (legs) jacobian_ = falcon::Jacobian(*legs);
  status_ = st;
  last_reply_ns_ = reply_ns;
  return true;
}

ConfigureResult FalconDevice::Configure(const FirmwareImage* firmware, const LoaderConfig& loader, std::string& log) {
  if (state_ != FalconState::kUnconfigured) {
    log += "Falcon: Configure() called twice\n";
    return ConfigureResult::kUsbError;
  }
  auto usb_fail = [&](const char* step, UsbStatus s) {
    LatchUsb(s);
    log += std::string("Falcon: ") + step + ": USB " + UsbStatusName(s) + "\n";
    return s == UsbStatus::kNoDevice ? ConfigureResult::kDisconnected : ConfigureResult::kUsbError;
  };
  UsbStatus s = ftdi::SetNormalMode(transport_);
  if (s != UsbStatus::kOk) return usb_fail("FTDI set-up (latency 1 ms, 1.5 MBd)", s);
  DeviceStatus st;
  switch (ProbeFirmware(transport_, st)) {
    case ProbeResult::kAnswering:
      log += "Falcon: firmware already loaded (it answers 16-byte packets)\n";
      status_ = st;
      state_ = FalconState::kInactive;
      return ConfigureResult::kOk;
    case ProbeResult::kNoDevice:
      return usb_fail("firmware probe", UsbStatus::kNoDevice);
    case ProbeResult::kIoError:
      return usb_fail("firmware probe", UsbStatus::kIoError);
    case ProbeResult::kSilent:
      break;
  }
  if (firmware == nullptr) {
    log +=
        "Falcon: no firmware is running (the Falcon forgets it at power-off); pass --firmware PATH with Novint's "
        "firmware file (e.g. nvent_firmware.bin); palpa does not ship it\n";
    return ConfigureResult::kNoFirmware;
  }
  log += "Falcon: no firmware running; uploading " + firmware->path + " (" + std::to_string(firmware->bytes.size()) +
         " bytes)\n";
  const LoadReport report = LoadFirmware(transport_, *firmware, loader);
  log += "Falcon: " + report.Message(loader.attempts) + "\n";
  if (!report.ok) return ConfigureResult::kLoadFailed;  // stays Unconfigured: nothing runs to stop
  state_ = FalconState::kInactive;
  return ConfigureResult::kOk;
}

HomeResult FalconDevice::Home(const std::atomic<bool>& stop, double timeout_s) {
  if (state_ != FalconState::kInactive) return HomeResult::kFault;
  MotorCommand cmd;
  cmd.control = falcon::kControlHoming | kLedHoming;
  const std::int64_t start = transport_.NowNs();
  const auto timeout_ns = static_cast<std::int64_t>(timeout_s * 1e9);
  bool have_first = false;
  bool moved = false;
  std::array<std::int16_t, 3> first{};
  DeviceStatus st;
  for (;;) {
    if (stop.load(std::memory_order_acquire)) {
      Send({{0, 0, 0}, falcon::kControlHoming});
      return HomeResult::kStopped;
    }
    if (!Send(cmd) || !Receive(st)) {
      (void)WriteZeroAfterFault();
      return HomeResult::kFault;
    }
    if (!have_first) {
      first = st.encoders;
      have_first = true;
    } else if (st.encoders != first) {
      moved = true;
    }
    status_ = st;
    if (st.AllHomed()) break;
    if (transport_.NowNs() - start > timeout_ns) {
      FaultInfo f;
      f.code = moved ? FalconFault::kHomingTimeout : FalconFault::kEncodersFrozen;
      f.waited_ns = transport_.NowNs() - start;
      f.homed = st.homed;
      f.encoders = st.encoders;
      Latch(f);
      (void)WriteZeroAfterFault();
      return moved ? HomeResult::kTimeout : HomeResult::kFrozen;
    }
  }
  // Homing resets the encoders' zero: the pose and the jump reference start here.
  last_reply_ns_ = transport_.NowNs();
  const falcon::FkOutcome fk = falcon::ForwardKinematics(falcon::EncodersToTheta(st.encoders), grip_m_, config_.fk);
  if (!fk.result) {
    FaultInfo f;
    f.code = FalconFault::kKinematics;
    f.fk_error = static_cast<int>(fk.error);
    f.encoders = st.encoders;
    Latch(f);
    (void)WriteZeroAfterFault();
    return HomeResult::kFault;
  }
  grip_m_ = fk.result->p_m;
  status_ = st;
  state_ = FalconState::kReady;
  // Homed (blue): wait for the pull-out, with the full safety checks on every reply.
  cmd.control = falcon::kControlHoming | kLedReady;
  for (;;) {
    if (!Send(cmd) || !Receive(st) || !UpdatePose(st, transport_.NowNs())) {
      (void)WriteZeroAfterFault();
      return HomeResult::kFault;
    }
    if (grip_m_[2] > config_.activate_above_z_m) return HomeResult::kHomed;
    if (stop.load(std::memory_order_acquire)) return HomeResult::kStopped;
    if (transport_.NowNs() - start > timeout_ns) {
      FaultInfo f;
      f.code = FalconFault::kHomingTimeout;
      f.waited_ns = transport_.NowNs() - start;
      f.homed = st.homed;
      f.encoders = st.encoders;
      Latch(f);
      (void)WriteZeroAfterFault();
      return HomeResult::kTimeout;
    }
  }
}

bool FalconDevice::Activate() {
  if (state_ != FalconState::kReady) return false;
  state_ = FalconState::kActive;
  active_start_ns_ = transport_.NowNs();
  still_since_ns_ = active_start_ns_;
  ticks_ = 0;
  command_ = {{0, 0, 0}, static_cast<std::uint8_t>(falcon::kControlHoming | kLedActive)};
  return true;
}

device::IoStatus FalconDevice::DoRead(device::HipReading& out) {
  if (state_ == FalconState::kActive && config_.tick_limit != 0 && ticks_ >= config_.tick_limit)
    return device::IoStatus::kEnd;
  if (state_ != FalconState::kActive) {
    if (state_ != FalconState::kFault) {
      FaultInfo f;
      f.code = FalconFault::kNotActive;
      Latch(f);
    }
    return device::IoStatus::kError;
  }
  // First tick (or after a write that was not sent): keep-alive with the current command.
  if (!outstanding_ && !Send(command_)) return device::IoStatus::kError;
  DeviceStatus st;
  if (!Receive(st)) return device::IoStatus::kError;
  const std::int64_t now = transport_.NowNs();
  const std::array<std::int16_t, 3> before = status_.encoders;
  if (!UpdatePose(st, now)) return device::IoStatus::kError;
  if (!CheckEncodersMove(before, st.encoders, now)) return device::IoStatus::kError;
  for (std::size_t a = 0; a < 3; ++a) out.hip_m[a] = grip_m_[a] - config_.workspace_origin_m[a];
  out.t_s = static_cast<double>(now - active_start_ns_) * 1e-9;
  out.buttons = st.buttons;
  ++ticks_;
  return device::IoStatus::kOk;
}

bool FalconDevice::CheckEncodersMove(const std::array<std::int16_t, 3>& before,
                                     const std::array<std::int16_t, 3>& now_counts, std::int64_t now_ns) {
  if (stale_ramp_start_ns_ >= 0) {  // found stale: fading, whatever the encoders do now
    if (now_ns - stale_ramp_start_ns_ < config_.stale_ramp_ns) return true;
    Latch(stale_fault_);
    return false;
  }
  // command_ is the command this reply answers: the window restarts whenever the torque was zero
  // (an idle grip may rest still for ever) or an encoder moved.
  if (config_.stale_encoder_ns <= 0 || now_counts != before || command_.counts == std::array<std::int16_t, 3>{}) {
    still_since_ns_ = now_ns;
    return true;
  }
  if (now_ns - still_since_ns_ < config_.stale_encoder_ns) return true;
  FaultInfo f;
  f.code = FalconFault::kEncodersStale;
  f.waited_ns = now_ns - still_since_ns_;
  f.encoders = now_counts;
  f.command = command_.counts;
  f.force_n = last_force_n_;
  if (config_.stale_ramp_ns > 0) {
    stale_fault_ = f;
    stale_ramp_start_ns_ = now_ns;
    stale_ramp_from_ = command_.counts;
    return true;
  }
  Latch(f);
  return false;
}

device::IoStatus FalconDevice::DoWrite(const std::array<double, 3>& force_n) {
  last_force_n_ = force_n;
  MotorCommand cmd;
  if (state_ == FalconState::kActive) {
    cmd.control = falcon::kControlHoming | kLedActive;
    const bool zero = force_n[0] == 0.0 && force_n[1] == 0.0 && force_n[2] == 0.0;
    if (stale_ramp_start_ns_ >= 0) {
      // Stale encoders: the held command fades (integer counts, truncated towards zero, so the
      // torque never grows); a zero force from the loop (e-stop, stop) still zeroes it at once.
      const std::int64_t left = config_.stale_ramp_ns - (transport_.NowNs() - stale_ramp_start_ns_);
      for (std::size_t a = 0; a < 3; ++a)
        cmd.counts[a] =
            zero || left <= 0
                ? std::int16_t{0}
                : static_cast<std::int16_t>(std::int64_t{stale_ramp_from_[a]} * left / config_.stale_ramp_ns);
    } else if (!zero) {
      const auto tau = jacobian_ok_ ? falcon::ForceToTorque(jacobian_, force_n) : std::nullopt;
      if (tau) {
        bool saturated = false;
        cmd.counts = falcon::TorqueToCounts(*tau, saturated);
        if (saturated) ++counters_.saturated_commands;
      } else {
        ++counters_.singular_poses;  // zero torque rather than a wild one
      }
    }
    if (outstanding_) {
      // The reply to the previous command was not read (no Read in between): read it now so that
      // the request/response pairing holds.
      DeviceStatus st;
      if (!Receive(st) || !UpdatePose(st, transport_.NowNs())) return WriteZeroAfterFault();
    }
    return Send(cmd) ? device::IoStatus::kOk : device::IoStatus::kError;
  }
  if (state_ == FalconState::kFault) return WriteZeroAfterFault();
  return device::IoStatus::kError;  // not active: nothing may move the motors
}

device::IoStatus FalconDevice::WriteZeroAfterFault() {
  // Best effort after a fault: zero torque with the fault LEDs. A lost device cannot take it.
  command_ = {{0, 0, 0}, static_cast<std::uint8_t>(falcon::kControlHoming | kLedFault)};
  if (fault_.code == FalconFault::kDisconnected) return device::IoStatus::kError;
  const falcon::Packet p = falcon::EncodeCommand(command_);
  std::size_t written = 0;
  const UsbStatus s = transport_.BulkOut(p, written, config_.reply_timeout_ns / 1000);
  zero_sent_after_fault_ = s == UsbStatus::kOk && written == p.size();
  return zero_sent_after_fault_ ? device::IoStatus::kOk : device::IoStatus::kError;
}

bool FalconDevice::EmergencyZero() noexcept {
  const falcon::Packet p =
      falcon::EncodeCommand({{0, 0, 0}, static_cast<std::uint8_t>(falcon::kControlHoming | kLedFault)});
  std::size_t written = 0;
  return transport_.BulkOut(p, written, config_.reply_timeout_ns / 1000) == UsbStatus::kOk && written == p.size();
}

void FalconDevice::Shutdown() {
  if (state_ == FalconState::kFinalized) return;
  const bool gone = state_ == FalconState::kUnconfigured ||
                    (state_ == FalconState::kFault && fault_.code == FalconFault::kDisconnected);
  if (!gone) {
    // Zero torque, LEDs off; the homing bit keeps the homed state for a later run.
    const falcon::Packet p = falcon::EncodeCommand({{0, 0, 0}, falcon::kControlHoming});
    command_ = {{0, 0, 0}, falcon::kControlHoming};
    std::size_t written = 0;
    if (transport_.BulkOut(p, written, config_.reply_timeout_ns / 1000) == UsbStatus::kOk) {
      // Drain replies (ours and any outstanding one) for one timeout; failures do not matter now.
      const std::int64_t deadline = transport_.NowNs() + config_.reply_timeout_ns;
      for (int i = 0; i < kMaxTransfersPerReply && transport_.NowNs() < deadline; ++i) {
        std::array<std::uint8_t, kBulkInBytes> raw{};
        std::size_t got = 0;
        const UsbStatus s = transport_.BulkIn(raw, got, (deadline - transport_.NowNs() + 999) / 1000);
        if (s == UsbStatus::kNoDevice || s == UsbStatus::kIoError) break;
        reader_.PushUsbTransfer(std::span<const std::uint8_t>(raw.data(), got));
        falcon::Packet frame{};
        int frames = 0;
        while (reader_.Next(frame)) ++frames;
        if (frames > 0 && !outstanding_) break;
        if (frames > 0) outstanding_ = false;
      }
    }
  }
  outstanding_ = false;
  state_ = FalconState::kFinalized;
}

std::string FalconDevice::FaultMessage() const {
  const FaultInfo& f = fault_;
  const std::string where = std::string(" (state ") + FalconStateName(f.state) + ", after " +
                            std::to_string(f.exchange) + " packet exchanges)";
  std::string zero;
  if (f.code == FalconFault::kDisconnected) {
    zero =
        "; zero torque could not be sent — the Falcon keeps its last command until it is powered off or "
        "reconnected (no device-side watchdog is documented)";
  } else {
    zero = zero_sent_after_fault_ ? "; zero torque sent" : "; zero torque could not be confirmed";
  }
  switch (f.code) {
    case FalconFault::kNone:
      return {};
    case FalconFault::kReplyTimeout:
      return "Falcon stopped replying: no valid reply " + Ms(f.waited_ns) + " after a command (limit " +
             Ms(config_.reply_timeout_ns) + ")" + where + zero;
    case FalconFault::kDisconnected:
      return "Falcon disconnected (USB: no device)" + where + zero;
    case FalconFault::kUsbError:
      return std::string("Falcon USB transfer failed (") + UsbStatusName(f.usb) + ")" + where + zero;
    case FalconFault::kEncoderJump:
      return "Falcon encoder " + std::to_string(f.axis) + " jumped by " + std::to_string(f.jump_counts) +
             " counts in " + Ms(f.waited_ns) + " (physical bound " + std::to_string(f.bound_counts) +
             " counts); encoders now " + Encoders(f.encoders) + where + zero;
    case FalconFault::kLostHoming:
      return "Falcon lost its homing: axis " + std::to_string(f.axis) + " no longer reports homed (flags 0x" +
             std::to_string(f.homed) + ")" + where + zero;
    case FalconFault::kKinematics:
      return "Falcon forward kinematics found no grip position for encoders " + Encoders(f.encoders) +
             (f.fk_error == static_cast<int>(falcon::FkError::kSingular) ? " (singular pose)" : " (no convergence)") +
             where + zero;
    case FalconFault::kEncodersFrozen:
      return "Falcon homing failed: the firmware answers but no encoder changed in " + Ms(f.waited_ns) +
             " (encoders stay at " + Encoders(f.encoders) +
             "). Either nobody moved the grip, or the firmware runs with frozen encoders (a known failure after a "
             "bad load): power-cycle the Falcon and load the firmware again" +
             zero;
    case FalconFault::kEncodersStale: {
      char force[96];
      std::snprintf(force, sizeof force, "%.3f N (%.3f, %.3f, %.3f)",
                    std::sqrt(f.force_n[0] * f.force_n[0] + f.force_n[1] * f.force_n[1] + f.force_n[2] * f.force_n[2]),
                    f.force_n[0], f.force_n[1], f.force_n[2]);
      return "device fault: encoders frozen at " + Encoders(f.encoders) + " for " + Ms(f.waited_ns) +
             " while commanding torque " + Encoders(f.command) + " counts for a force of " + force +
             ": a Falcon under torque never reads exactly still (limit " + Ms(config_.stale_encoder_ns) +
             "), so the readings no longer follow the grip (firmware stalled or encoders lost); the held torque "
             "faded to zero over " +
             Ms(config_.stale_ramp_ns) + where + zero;
    }
    case FalconFault::kHomingTimeout:
      if (f.homed == falcon::kAllHomed)
        return "Falcon homed, but the grip was not pulled out (z > " + std::to_string(config_.activate_above_z_m) +
               " m) within " + Ms(f.waited_ns) + "; forces stay off" + zero;
      return "Falcon homing timed out after " + Ms(f.waited_ns) + ": homed flags 0x" + std::to_string(f.homed) +
             " of 0x7; move the grip all the way out, then push it straight in" + zero;
    case FalconFault::kNotActive:
      return "Falcon read before Activate() (programming error)" + zero;
  }
  return "Falcon fault";
}

}  // namespace palpa::device_falcon
