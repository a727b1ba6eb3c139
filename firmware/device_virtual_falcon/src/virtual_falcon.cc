#include "palpa/device_virtual_falcon/virtual_falcon.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <utility>

#include "palpa/device_falcon/ftdi.h"

namespace palpa::device_virtual_falcon {
namespace {

using device_falcon::UsbStatus;
using falcon::Vec3;
namespace ftdi = device_falcon::ftdi;

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kSubstepNs = 100'000;                       // mechanics integration step, 0.1 ms
constexpr std::int64_t kDeviceTurnaroundNs = 200'000;              // command in → reply ready (serial + DSP)
constexpr std::array<std::uint8_t, 2> kFtdiStatus = {0x31, 0x60};  // CTS|DSR + low nibble 1; THRE|TEMT
constexpr int kAmplifierLimit = 4096;
constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kHomingOutDeg = 55.0;  // "all the way out"
constexpr double kHomingIndexDeg = 35.0;
constexpr std::int16_t kJumpCounts = 3000;

constexpr Vec3 kGestureOut = {0.0, 0.0, 0.168};
constexpr Vec3 kGestureIn = {0.0, 0.0, 0.100};
constexpr std::int64_t kGestureLegNs = 600 * kMs;
constexpr Vec3 kPulledOut = {0.0, 0.0, 0.174};  // beyond the host's 0.170 m activation height
constexpr std::int64_t kPullOutNs = 500 * kMs;
constexpr std::int64_t kBlendNs = 500 * kMs;

// Serial time of n bytes (10 bits each) at an FTDI divisor of 3 MHz.
std::int64_t SerialNs(std::size_t n, std::uint16_t divisor) {
  const double baud = 3e6 / static_cast<double>(divisor == 0x4138 ? 312.5 : (divisor & 0x3FFF));
  return static_cast<std::int64_t>(static_cast<double>(n) * 10.0 / baud * 1e9);
}

double MinimumJerk(double tau) {
  tau = std::clamp(tau, 0.0, 1.0);
  return tau * tau * tau * (10 + tau * (-15 + 6 * tau));
}

Vec3 Lerp(const Vec3& a, const Vec3& b, double s) {
  return {a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s, a[2] + (b[2] - a[2]) * s};
}

}  // namespace

std::expected<std::vector<FaultSpec>, std::string> ParseFaults(std::string_view text) {
  std::vector<FaultSpec> out;
  while (!text.empty()) {
    const std::size_t comma = text.find(',');
    const std::string_view item = text.substr(0, comma);
    text = comma == std::string_view::npos ? std::string_view{} : text.substr(comma + 1);
    const std::size_t at = item.find('@');
    const std::string_view name = item.substr(0, at);
    static constexpr std::pair<std::string_view, FaultKind> kNames[] = {
        {"drop", FaultKind::kDrop},       {"split", FaultKind::kSplit},   {"garbage", FaultKind::kGarbage},
        {"corrupt", FaultKind::kCorrupt}, {"unplug", FaultKind::kUnplug}, {"frozen", FaultKind::kFrozen},
        {"jump", FaultKind::kJump},       {"echo", FaultKind::kEcho},     {"echo-once", FaultKind::kEchoOnce}};
    const auto* it = std::find_if(std::begin(kNames), std::end(kNames), [&](const auto& n) { return n.first == name; });
    if (it == std::end(kNames))
      return std::unexpected("--fault: unknown fault '" + std::string(item) +
                             "' (drop, split, garbage, corrupt, unplug, frozen, jump, echo, echo-once; KIND@N)");
    FaultSpec f;
    f.kind = it->second;
    if (at != std::string_view::npos) {
      const std::string_view num = item.substr(at + 1);
      std::uint64_t v = 0;
      bool ok = !num.empty() && num.size() <= 12;
      for (const char ch : num) {
        if (ch < '0' || ch > '9') ok = false;
        v = v * 10 + static_cast<std::uint64_t>(ch - '0');
      }
      if (!ok) return std::unexpected("--fault: '" + std::string(item) + "': N must be a whole number");
      f.at = v;
    } else if (f.kind != FaultKind::kFrozen) {
      return std::unexpected("--fault: '" + std::string(item) + "' needs @N");
    }
    out.push_back(f);
  }
  return out;
}

VirtualFalcon::VirtualFalcon(VirtualFalconConfig config)
    : config_(std::move(config)),
      period_ns_(static_cast<std::int64_t>(std::llround(1e9 / config_.rate_hz))),
      dsp_(config_.firmware_loaded ? Dsp::kRunning : Dsp::kBootRom),
      p_(config_.power_up_grip_m) {
  if (auto legs = falcon::InverseKinematics(p_)) {
    for (std::size_t i = 0; i < 3; ++i) encoder_zero_[i] = falcon::ThetaToEncoder((*legs)[i].theta1);
  }
  if (dsp_ == Dsp::kRunning) {
    baud_ = ftdi::kBaud1M5;  // a previous session left the bridge in normal mode
    latency_ms_ = 1;
  }
}

bool VirtualFalcon::FaultAt(FaultKind kind, std::uint64_t at_most) const {
  for (const FaultSpec& f : config_.faults)
    if (f.kind == kind && f.at <= at_most) return true;
  return false;
}

bool VirtualFalcon::Unplugged() const { return run_started_ && FaultAt(FaultKind::kUnplug, run_exchanges_); }

std::int64_t VirtualFalcon::ReplyDelayNs() const {
  // The FTDI holds a short packet until its latency timer expires (docs/falcon.md §1.4).
  return kDeviceTurnaroundNs + std::max<std::int64_t>(0, latency_ms_ - 1) * kMs;
}

void VirtualFalcon::Queue(std::int64_t avail_ns, std::span<const std::uint8_t> bytes) {
  while (!bytes.empty() && seg_count_ < kSegments) {
    Segment& s = segments_[(seg_head_ + seg_count_) % kSegments];
    s.avail_ns = avail_ns;
    s.len = static_cast<std::uint8_t>(std::min(bytes.size(), s.bytes.size()));
    std::copy_n(bytes.begin(), s.len, s.bytes.begin());
    bytes = bytes.subspan(s.len);
    ++seg_count_;
  }
}

UsbStatus VirtualFalcon::DoControlOut(std::uint8_t request, std::uint16_t value, int) {
  if (Unplugged()) return UsbStatus::kNoDevice;
  switch (request) {
    case ftdi::kReqReset:
      if (value == ftdi::kPurgeRx) seg_count_ = 0;  // device→host data dropped
      if (value == ftdi::kPurgeTx) commands_in_.Clear();
      break;
    case ftdi::kReqModemCtrl:
      if ((value & 0x0100) != 0) {
        const bool dtr = (value & 0x0001) != 0;
        if (dtr && !dtr_) {
          // A DTR rising edge restarts the DSP into its boot ROM: any firmware is gone.
          dsp_ = Dsp::kBootRom;
          handshake_ = {};
          homed_ = 0;
          axis_out_ = {};
        }
        dtr_ = dtr;
      }
      break;
    case ftdi::kReqSetBaudRate:
      baud_ = value;
      break;
    case ftdi::kReqSetLatency:
      latency_ms_ = static_cast<std::uint16_t>(std::clamp<int>(value, 1, 255));
      break;
    default:
      break;  // data format, flow control: accepted, no effect here
  }
  return UsbStatus::kOk;
}

void VirtualFalcon::BootByte(std::uint8_t b) {
  switch (dsp_) {
    case Dsp::kBootRom: {
      if (baud_ != ftdi::kBaud9600) return;  // wrong baud: the ROM sees noise
      handshake_ = {handshake_[1], handshake_[2], b};
      if (handshake_ == std::array<std::uint8_t, 3>{0x0A, 0x43, 0x0D}) {
        static constexpr std::array<std::uint8_t, 4> kReply = {0x0A, 0x44, 0x2C, 0x0D};
        Queue(now_ns_ + SerialNs(4, baud_) + latency_ms_ * kMs, kReply);
        dsp_ = Dsp::kAwaitAutobaud;
      }
      return;
    }
    case Dsp::kAwaitAutobaud: {
      if (baud_ != ftdi::kBaud140k || b != 0x41) return;
      const std::array<std::uint8_t, 1> echo = {b};
      Queue(now_ns_ + SerialNs(1, baud_) + latency_ms_ * kMs, echo);
      dsp_ = Dsp::kStream;
      stream_bytes_ = 0;
      words_left_ = 11;  // key, 8 reserved words, 32-bit entry point
      expect_block_size_ = false;
      have_low_byte_ = false;
      ++upload_attempts_;
      return;
    }
    case Dsp::kStream: {
      if (baud_ != ftdi::kBaud140k) return;
      std::uint8_t echo = b;
      for (const FaultSpec& f : config_.faults) {
        const bool applies = f.kind == FaultKind::kEcho || (f.kind == FaultKind::kEchoOnce && upload_attempts_ == 1);
        if (applies && f.at == stream_bytes_) echo = static_cast<std::uint8_t>(b ^ 0x5A);
      }
      echo_buf_[echo_len_++] = echo;
      ++stream_bytes_;
      if (!have_low_byte_) {
        low_byte_ = b;
        have_low_byte_ = true;
        return;
      }
      have_low_byte_ = false;
      const auto word = static_cast<std::uint16_t>(low_byte_ | (b << 8));
      if (expect_block_size_) {
        if (word == 0) {
          dsp_ = Dsp::kRunning;  // end block: the boot ROM jumps to the entry point
          ++uploads_completed_;
          homed_ = 0;
          axis_out_ = {};
          return;
        }
        words_left_ = std::uint64_t{word} + 2;  // destination (2 words) + data
        expect_block_size_ = false;
      } else if (--words_left_ == 0) {
        expect_block_size_ = true;
      }
      return;
    }
    case Dsp::kRunning:
      return;
  }
}

UsbStatus VirtualFalcon::DoBulkOut(std::span<const std::uint8_t> bytes, std::size_t& written, std::int64_t) {
  if (Unplugged()) return UsbStatus::kNoDevice;
  written = bytes.size();
  if (dsp_ != Dsp::kRunning) {
    echo_len_ = 0;
    for (const std::uint8_t b : bytes) {
      if (dsp_ == Dsp::kRunning) break;  // bytes after the end block: ignored
      BootByte(b);
    }
    if (echo_len_ > 0 && dsp_ != Dsp::kAwaitAutobaud) {
      Queue(now_ns_ + SerialNs(echo_len_, baud_) + latency_ms_ * kMs, std::span(echo_buf_).first(echo_len_));
    }
    return UsbStatus::kOk;
  }
  if (baud_ != ftdi::kBaud1M5) return UsbStatus::kOk;  // firmware listens at 1.5 MBd only
  commands_in_.PushPayload(bytes);
  falcon::Packet p{};
  while (commands_in_.Next(p)) {
    if (const auto cmd = falcon::DecodeCommand(p)) Exchange(*cmd);
    if (Unplugged()) return UsbStatus::kNoDevice;
  }
  return UsbStatus::kOk;
}

UsbStatus VirtualFalcon::DoBulkIn(std::span<std::uint8_t> buf, std::size_t& got, std::int64_t timeout_us) {
  if (Unplugged()) return UsbStatus::kNoDevice;
  const std::int64_t deadline = now_ns_ + timeout_us * 1000;
  if (seg_count_ > 0 && segments_[seg_head_].avail_ns <= deadline) {
    now_ns_ = std::max(now_ns_, segments_[seg_head_].avail_ns);
    buf[0] = kFtdiStatus[0];
    buf[1] = kFtdiStatus[1];
    got = 2;
    // Everything ready by now goes in this USB packet, up to 62 payload bytes.
    while (seg_count_ > 0 && segments_[seg_head_].avail_ns <= now_ns_) {
      Segment& s = segments_[seg_head_];
      const std::size_t n = std::min<std::size_t>(s.len, buf.size() - got);
      std::copy_n(s.bytes.begin(), n, buf.begin() + static_cast<std::ptrdiff_t>(got));
      got += n;
      if (n < s.len) {
        std::copy(s.bytes.begin() + static_cast<std::ptrdiff_t>(n), s.bytes.begin() + s.len, s.bytes.begin());
        s.len = static_cast<std::uint8_t>(s.len - n);
        break;
      }
      seg_head_ = (seg_head_ + 1) % kSegments;
      --seg_count_;
    }
    return UsbStatus::kOk;
  }
  // Nothing to send: the FTDI answers with its 2 status bytes when the latency timer expires.
  const std::int64_t latency_ns = latency_ms_ * kMs;
  if (now_ns_ + latency_ns <= deadline) {
    now_ns_ += latency_ns;
    buf[0] = kFtdiStatus[0];
    buf[1] = kFtdiStatus[1];
    got = 2;
    return UsbStatus::kOk;
  }
  now_ns_ = deadline;
  return UsbStatus::kTimeout;
}

Vec3 VirtualFalcon::HandTarget(std::int64_t t_ns) const {
  const double since_s = static_cast<double>(t_ns - hand_phase_ns_) * 1e-9;
  auto start_point = [&] {
    if (config_.trace.empty()) return config_.workspace_origin_m;
    const auto& h = config_.trace.front().hip_m;
    const Vec3& o = config_.workspace_origin_m;
    return Vec3{o[0] + h[0], o[1] + h[1], o[2] + h[2]};
  };
  switch (hand_) {
    case Hand::kRest:
      return config_.power_up_grip_m;
    case Hand::kHoming: {
      const double leg_s = static_cast<double>(kGestureLegNs) * 1e-9;
      if (since_s < leg_s) return Lerp(hand_from_, kGestureOut, MinimumJerk(since_s / leg_s));
      return Lerp(kGestureOut, kGestureIn, MinimumJerk((since_s - leg_s) / leg_s));
    }
    case Hand::kPullOut:
      return Lerp(hand_from_, kPulledOut, MinimumJerk(since_s / (static_cast<double>(kPullOutNs) * 1e-9)));
    case Hand::kTrace: {
      if (config_.trace.size() < 2) return start_point();
      const auto h = trace::HipAt(config_.trace, since_s, trace_cursor_);
      const Vec3& o = config_.workspace_origin_m;
      // The hand blends in from where homing left it over the first kBlendNs (no step).
      const Vec3 s0 = start_point();
      const double w = 1.0 - MinimumJerk(since_s / (static_cast<double>(kBlendNs) * 1e-9));
      return {o[0] + h[0] + (hand_from_[0] - s0[0]) * w, o[1] + h[1] + (hand_from_[1] - s0[1]) * w,
              o[2] + h[2] + (hand_from_[2] - s0[2]) * w};
    }
  }
  return p_;
}

void VirtualFalcon::Integrate(std::int64_t to_ns) {
  if (!physics_started_) {
    physics_ns_ = to_ns;  // mechanics start with the first runtime packet
    hand_prev_ = HandTarget(to_ns);
    physics_started_ = true;
    return;
  }
  const Vec3 tau = falcon::CountsToTorque(command_.counts);  // already clamped by the amplifier
  const HandModel& hm = config_.hand;
  int steps = 0;
  while (physics_ns_ < to_ns && steps < 1'000'000) {
    ++steps;
    const std::int64_t dt_ns = std::min(kSubstepNs, to_ns - physics_ns_);
    const double dt = static_cast<double>(dt_ns) * 1e-9;
    const Vec3 h = HandTarget(physics_ns_ + dt_ns);
    Vec3 force{};
    if (const auto legs = falcon::InverseKinematics(p_)) {
      motor_force_n_ = falcon::TorqueToForce(falcon::Jacobian(*legs), tau);
    }
    for (std::size_t a = 0; a < 3; ++a) {
      const double h_dot = (h[a] - hand_prev_[a]) / dt;
      force[a] = hm.stiffness_n_per_m * (h[a] - p_[a]) + hm.damping_n_s_per_m * (h_dot - v_[a]) + motor_force_n_[a];
    }
    hand_prev_ = h;
    Vec3 next = p_;
    for (std::size_t a = 0; a < 3; ++a) {
      v_[a] += force[a] / hm.mass_kg * dt;  // semi-implicit Euler
      next[a] += v_[a] * dt;
    }
    if (falcon::InverseKinematics(next)) {
      p_ = next;
    } else {
      v_ = {0.0, 0.0, 0.0};  // a mechanical stop
    }
    physics_ns_ += dt_ns;
  }
}

void VirtualFalcon::UpdateEncoders() {
  if (FaultAt(FaultKind::kFrozen, firmware_exchanges_)) return;  // the firmware stopped reading them
  const auto legs = falcon::InverseKinematics(p_);
  if (!legs) return;
  const bool homing = (command_.control & falcon::kControlHoming) != 0;
  for (std::size_t i = 0; i < 3; ++i) {
    const double theta = (*legs)[i].theta1;
    const auto bit = static_cast<std::uint8_t>(1u << i);
    if (homing && (homed_ & bit) == 0) {
      if (theta >= kHomingOutDeg * kDeg) axis_out_[i] = true;
      if (axis_out_[i] && theta <= kHomingIndexDeg * kDeg) {
        homed_ |= bit;
        encoder_zero_[i] = 0.0;  // from now on encoder 0 ↔ θ1 = 35°
      }
    }
    const double count = std::round(falcon::ThetaToEncoder(theta) - encoder_zero_[i]);
    encoders_[i] = static_cast<std::int16_t>(std::clamp(count, -32768.0, 32767.0));
  }
}

void VirtualFalcon::Exchange(const falcon::MotorCommand& received) {
  if (last_cmd_ns_ >= 0) now_ns_ = std::max(now_ns_, last_cmd_ns_ + period_ns_);
  last_cmd_ns_ = now_ns_;
  Integrate(now_ns_);  // up to now under the previous command

  falcon::MotorCommand cmd = received;
  for (std::int16_t& c : cmd.counts) {
    if (c > kAmplifierLimit || c < -kAmplifierLimit) {
      ++amplifier_clamps_;
      c = static_cast<std::int16_t>(std::clamp<int>(c, -kAmplifierLimit, kAmplifierLimit));
    }
  }
  if ((cmd.control & falcon::kControlHoming) == 0) {
    homed_ = 0;  // "the homing bit must be set in each packet for the Falcon to stay homed"
    axis_out_ = {};
  }
  if (cmd.counts != std::array<std::int16_t, 3>{} && homed_ != falcon::kAllHomed) ++torque_before_homed_;
  command_ = cmd;
  ++commands_;

  const auto leds = static_cast<std::uint8_t>(cmd.control & (falcon::kLedRed | falcon::kLedGreen | falcon::kLedBlue));
  if (leds != leds_ || leds_log_count_ == 0) {
    if (leds_log_count_ < leds_log_.size()) leds_log_[leds_log_count_++] = {now_ns_, leds, homed_};
    leds_ = leds;
  }
  // The hand reacts to the LEDs like a user following the instructions.
  const Vec3 target_now = HandTarget(now_ns_);
  if (leds == falcon::kLedRed && hand_ == Hand::kRest) {
    hand_ = Hand::kHoming;
    hand_phase_ns_ = now_ns_;
    hand_from_ = target_now;
  } else if (leds == falcon::kLedBlue && (hand_ == Hand::kRest || hand_ == Hand::kHoming)) {
    hand_ = Hand::kPullOut;
    hand_phase_ns_ = now_ns_;
    hand_from_ = target_now;
  } else if (leds == falcon::kLedGreen && hand_ != Hand::kTrace) {
    hand_ = Hand::kTrace;
    hand_phase_ns_ = now_ns_;
    hand_from_ = target_now;
    trace_cursor_ = 0;
    run_started_ = true;
    run_exchanges_ = 0;
  }

  UpdateEncoders();
  ++firmware_exchanges_;

  falcon::DeviceStatus st;
  st.encoders = encoders_;
  st.homed = homed_;
  // The grip buttons the hand holds: the trace's column at the hand's place in it (4 bits on the wire).
  if (hand_ == Hand::kTrace && !config_.trace.empty())
    st.buttons = config_.trace[std::min(trace_cursor_, config_.trace.size() - 1)].buttons;
  const std::uint64_t n = run_exchanges_;
  if (run_started_) {
    if (FaultAt(FaultKind::kJump, n))
      st.encoders[1] = static_cast<std::int16_t>(std::clamp(st.encoders[1] + kJumpCounts, -32768, 32767));
    ++run_exchanges_;
  }
  if (run_started_ && FaultAt(FaultKind::kDrop, n)) return;  // the reply never comes

  falcon::Packet reply = falcon::EncodeStatus(st);
  auto exactly = [&](FaultKind kind) {
    if (!run_started_) return false;
    for (const FaultSpec& f : config_.faults)
      if (f.kind == kind && f.at == n) return true;
    return false;
  };
  if (exactly(FaultKind::kCorrupt)) reply[15] = falcon::kNibbleBase;  // '>' lost: no valid frame
  const std::int64_t ready = now_ns_ + ReplyDelayNs();
  if (exactly(FaultKind::kGarbage)) {
    // A stray '<', a frame cut short and line noise, all in front of the reply.
    static constexpr std::array<std::uint8_t, 13> kJunk = {0x3C, 0x41, 0x42, 0x00, 0xFF, 0x3E, 0x3C,
                                                           0x41, 0x41, 0x50, 0x3C, 0x13, 0x3E};
    std::array<std::uint8_t, kJunk.size() + falcon::kPacketBytes> both{};
    std::copy(kJunk.begin(), kJunk.end(), both.begin());
    std::copy(reply.begin(), reply.end(), both.begin() + kJunk.size());
    Queue(ready, both);
  } else if (run_started_ && FaultAt(FaultKind::kSplit, n)) {
    // Two IN transfers; the split point walks through 1..15 so every cut is exercised.
    const auto cut = static_cast<std::size_t>(1 + n % 15);
    Queue(ready, std::span<const std::uint8_t>(reply).first(cut));
    Queue(ready + 50'000, std::span<const std::uint8_t>(reply).subspan(cut));
  } else {
    Queue(ready, reply);
  }
  ++replies_;
}

}  // namespace palpa::device_virtual_falcon
