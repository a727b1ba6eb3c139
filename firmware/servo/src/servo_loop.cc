#include "palpa/servo/servo_loop.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <ctime>

namespace palpa::servo {
namespace {

constexpr std::int64_t kFullRingWaitNs = 100'000;  // lockstep replay waiting for the drain: 0.1 ms naps

// Lockstep replay only (not RT): a short relative sleep while the drain catches up.
void Nap() { rt::SleepForNs(kFullRingWaitNs); }

// Restarts the proxy in a new field at the HIP `hip` (grid Q16.16). A HIP outside the object
// (φ ≥ 0) restarts it there (ProxyState reset, exact). A HIP inside is projected onto the surface
// by Newton steps p ← p − φ ∇φ/|∇φ|² (at most kSeedSteps samples, bounded), then nudged out to
// φ ≥ 0; if that lands on the surface (0 ≤ φ ≤ near, a readable gradient) the proxy is seeded
// there, seated, so the force k·(X_p − X_h) resumes under the swap ramp; otherwise (deeper than
// the band, no gradient) it restarts at the HIP and gives no force until the HIP has been outside
// (proxy.h). RT-safe: integer arithmetic, ≤ kSeedSteps + 2 samples. Returns true when seeded.
constexpr int kSeedSteps = 8;

bool SeedProxy(const ServoField& f, sampler::GridPos hip, proxy::ProxyState& state) {
  state = proxy::ProxyState{};
  sampler::GridPos p = hip;
  sampler::Sample s = f.sampler.At(p);
  if (!s.in_grid || s.phi >= 0) return false;
  constexpr std::int64_t kMinGrad2 = (std::int64_t{1} << 32) / 16;  // |∇φ| ≥ 1/4 voxel/voxel, Q32
  constexpr std::int32_t kClose = 1 << 10;                          // 1/64 voxel
  for (int step = 0; step < kSeedSteps + 2; ++step) {
    const std::int64_t g2 =
        std::int64_t{s.grad[0]} * s.grad[0] + std::int64_t{s.grad[1]} * s.grad[1] + std::int64_t{s.grad[2]} * s.grad[2];
    if (g2 < kMinGrad2) return false;
    if (s.phi >= 0 && s.phi <= f.params.near.value.raw()) {
      state.proxy = p;
      state.phi = s.phi;
      state.last_hip = hip;
      state.seated = true;
      state.valid = true;
      // The spring is already stretched: its force bounds last tick's (the proxy's rise limit
      // starts from it, not from 0), and the swap ramp fades the output from the old field's.
      state.pull = {fixed::Q16::FromRaw(proxy::SpringPullBound(f.params, p, hip))};
      return true;
    }
    // Aim a little outside (+1/64 voxel) so the last step lands at φ ≥ 0 rather than just below.
    const std::int64_t target = std::int64_t{s.phi} - kClose;
    std::array<std::int32_t*, 3> axes = {&p.x, &p.y, &p.z};
    for (std::size_t a = 0; a < 3; ++a) {
      const std::int64_t d = (target * s.grad[a] * 65536) / g2;  // |φ|,|g| < 2^23: < 2^62
      const std::int64_t moved = std::int64_t{*axes[a]} - d;
      *axes[a] = static_cast<std::int32_t>(std::clamp<std::int64_t>(moved, INT32_MIN, INT32_MAX));
    }
    s = f.sampler.At(p);
    if (!s.in_grid) return false;
  }
  state = proxy::ProxyState{};
  return false;
}

}  // namespace

const char* LoopStateName(LoopState s) {
  switch (s) {
    case LoopState::kRunning:
      return "running";
    case LoopState::kEstop:
      return "e-stop";
    case LoopState::kRamp:
      return "ramp";
    case LoopState::kFault:
      return "fault";
  }
  return "?";
}

const char* FaultCauseName(FaultCause c) {
  switch (c) {
    case FaultCause::kNone:
      return "none";
    case FaultCause::kOverruns:
      return "consecutive overruns";
    case FaultCause::kWatchdog:
      return "watchdog (tick did not complete)";
  }
  return "?";
}

const char* RunEndName(RunEnd e) {
  switch (e) {
    case RunEnd::kEnded:
      return "ended";
    case RunEnd::kStopped:
      return "stopped";
    case RunEnd::kDeviceError:
      return "device error";
    case RunEnd::kInvalidRate:
      return "invalid rate";
    case RunEnd::kOverrunFault:
      return "overrun fault";
    case RunEnd::kWatchdogFault:
      return "watchdog fault";
  }
  return "?";
}

ServoLoop::ServoLoop(const blob::FieldView& field, const proxy::ProxyParams& params, device::HapticDevice& device,
                     const ServoConfig& config, const std::atomic<bool>& stop)
    : initial_(field, params),
      frame_(proxy::GridFrame::Of(field)),
      device_(device),
      config_(config),
      clock_(config.clock != nullptr ? *config.clock : rt::MonotonicClock()),
      stop_(stop),
      ring_(config.telemetry_capacity),
      wake_(std::make_unique<WakeLatencyHistogram>()),  // value-initialised: every page touched now
      compute_(std::make_unique<ComputeHistogram>()) {
  if (config_.estop_release_ticks == 0) config_.estop_release_ticks = 1;
}

ServoLoop::ServoLoop(const blob::FieldView& field, const proxy::ProxyParams& params, device::HapticDevice& device,
                     std::size_t telemetry_capacity, const std::atomic<bool>& stop)
    : ServoLoop(field, params, device, ServoConfig{.telemetry_capacity = telemetry_capacity, .overrun_fault_limit = 0},
                stop) {}

std::array<std::span<const std::byte>, 3> ServoLoop::buffers() const {
  return {ring_.storage(), std::as_bytes(std::span<const WakeLatencyHistogram>(wake_.get(), 1)),
          std::as_bytes(std::span<const ComputeHistogram>(compute_.get(), 1))};
}

void ServoLoop::RequestFault(FaultCause cause) noexcept {
  int expected = 0;
  fault_request_.compare_exchange_strong(expected, static_cast<int>(cause), std::memory_order_acq_rel);
}

void ServoLoop::WriteZeroForce() {
  last_force_n_ = {0.0, 0.0, 0.0};
  if (device_.Write({0.0, 0.0, 0.0}) == device::IoStatus::kError) ++counters_.device_errors;
}

StepResult ServoLoop::EnterFault(FaultCause cause) {
  WriteZeroForce();
  if (loop_state_ != LoopState::kFault) {
    loop_state_ = LoopState::kFault;
    fault_ = cause;
  }
  return StepResult::kFault;
}

// The e-stop filter: asserted at once (a failed read counts as asserted), released only after
// estop_release_ticks consecutive released reads. Returns true while the force must be zero.
bool ServoLoop::ReadEstop(std::uint32_t& flags) {
  if (config_.estop == nullptr) return false;
  bool level = false;
  bool asserted = true;  // fail-safe
  if (config_.estop->Read(level) == gpio::GpioStatus::kOk) {
    asserted = level == config_.estop_active_high;
  } else {
    ++counters_.gpio_errors;
    flags |= kFlagGpioError;
  }
  if (asserted) {
    if (loop_state_ != LoopState::kEstop) ++counters_.estop_events;
    loop_state_ = LoopState::kEstop;
    release_count_ = 0;
    return true;
  }
  if (loop_state_ == LoopState::kEstop) {
    if (++release_count_ < config_.estop_release_ticks) return true;
    // Released: the proxy restarts at the HIP (ProxyState::valid = false) and the force ramps in.
    state_ = proxy::ProxyState{};
    ramp_tick_ = 0;
    loop_state_ = config_.ramp_ticks > 0 ? LoopState::kRamp : LoopState::kRunning;
  }
  return false;
}

StepResult ServoLoop::Tick(std::int64_t start_ns, std::int64_t wake_latency_ns) {
  tick_seq_.fetch_add(1, std::memory_order_acq_rel);  // odd: inside a tick
  TelemetrySample& s = pending_;
  s = TelemetrySample{};
  s.tick = tick_index_;
  s.wake_latency_ns = wake_latency_ns;

  StepResult result = StepResult::kRunning;
  if (config_.tick_line != nullptr) {
    tick_level_ = !tick_level_;
    if (config_.tick_line->Set(tick_level_) == gpio::GpioStatus::kError) {
      ++counters_.gpio_errors;
      s.flags |= kFlagGpioError;
    }
  }
  const bool estop = ReadEstop(s.flags);

  device::HipReading reading;
  const device::IoStatus read_status = device_.Read(reading);
  if (read_status != device::IoStatus::kOk) {
    if (read_status == device::IoStatus::kError) ++counters_.device_errors;
    WriteZeroForce();
    tick_seq_.fetch_add(1, std::memory_order_acq_rel);
    return read_status == device::IoStatus::kEnd ? StepResult::kEnded : StepResult::kDeviceError;
  }
  // The device call may have stalled while the watchdog latched a fault: no computed force now.
  if (const int f = fault_request_.load(std::memory_order_acquire); f != 0) {
    result = EnterFault(static_cast<FaultCause>(f));
    tick_seq_.fetch_add(1, std::memory_order_acq_rel);
    return result;
  }

  TakeOfferedField(reading, s.flags);
  s.row.t_s = reading.t_s;
  s.row.hip_m = reading.hip_m;
  s.buttons = reading.buttons;
  std::array<double, 3> force_n = {0.0, 0.0, 0.0};
  if (estop) {
    s.flags |= kFlagEstop;
    s.row.proxy_m = reading.hip_m;  // the proxy restarts here on release
    ++counters_.estop_ticks;
  } else {
    const proxy::TickResult r = proxy::ProxyTick(field_->sampler, field_->params, state_, frame_.ToGrid(reading.hip_m));
    // Q16.16 → double is exact (|raw| < 2^31 fits a 53-bit mantissa).
    force_n = {r.force[0].value.ToDouble(), r.force[1].value.ToDouble(), r.force[2].value.ToDouble()};
    if (loop_state_ == LoopState::kRamp) {
      ++ramp_tick_;
      const double scale = static_cast<double>(ramp_tick_) / static_cast<double>(config_.ramp_ticks);
      for (double& f : force_n) f *= scale;
      s.flags |= kFlagRamp;
      if (ramp_tick_ >= config_.ramp_ticks) loop_state_ = LoopState::kRunning;
    }
    if (swap_ramping_) {
      // Cross-fade from the force written just before the swap to the new field's: no step at the
      // swap, and every tick moves at most |f_new − f_hold|/ramp_ticks ≤ 2·max_force/ramp_ticks
      // more than the new field's own change.
      ++swap_ramp_tick_;
      const double scale = static_cast<double>(swap_ramp_tick_) / static_cast<double>(config_.swap_ramp_ticks);
      for (std::size_t a = 0; a < 3; ++a) force_n[a] = (1.0 - scale) * swap_hold_n_[a] + scale * force_n[a];
      s.flags |= kFlagSwapRamp;
      if (swap_ramp_tick_ >= config_.swap_ramp_ticks) swap_ramping_ = false;
    }
    s.row.proxy_m = frame_.ToMetres(r.proxy);
    s.row.contact = r.contact;
    if (r.clamped) {
      s.flags |= kFlagClamped;
      ++counters_.force_clamps;
    }
    if (r.contact) {
      ++counters_.contact_ticks;
      const double penetration_m = r.penetration.value.ToDouble() * frame_.voxel_m;
      if (penetration_m > counters_.max_penetration_m) counters_.max_penetration_m = penetration_m;
    }
  }
  s.row.force_n = force_n;
  last_force_n_ = force_n;
  const device::IoStatus write_status = device_.Write(force_n);
  const std::int64_t end_ns = clock_.NowNs();
  s.compute_ns = end_ns - start_ns;

  ++counters_.ticks;
  ++tick_index_;
  const double f = std::sqrt(force_n[0] * force_n[0] + force_n[1] * force_n[1] + force_n[2] * force_n[2]);
  if (f > counters_.max_force_n) counters_.max_force_n = f;
  compute_->Add(s.compute_ns);
  if (wake_latency_ns >= 0) wake_->Add(wake_latency_ns);

  if (write_status != device::IoStatus::kOk) {
    if (write_status == device::IoStatus::kError) ++counters_.device_errors;
    WriteZeroForce();
    result = write_status == device::IoStatus::kEnd ? StepResult::kEnded : StepResult::kDeviceError;
  }
  tick_seq_.fetch_add(1, std::memory_order_acq_rel);  // even: between ticks
  return result;
}

// At the start of a tick, before the proxy runs: the one exchange that hands a new field over.
void ServoLoop::TakeOfferedField(const device::HipReading& reading, std::uint32_t& flags) {
  if (offered_.load(std::memory_order_relaxed) == nullptr) return;  // the common case: one load
  const ServoField* next = offered_.exchange(nullptr, std::memory_order_acq_rel);
  if (next == nullptr) return;  // withdrawn in between
  field_ = next;
  frame_ = next->frame;
  if (SeedProxy(*next, frame_.ToGrid(reading.hip_m), state_)) ++counters_.swap_seeds;
  swap_ramp_tick_ = 0;
  swap_hold_n_ = last_force_n_;
  swap_ramping_ = config_.swap_ramp_ticks > 0;
  flags |= kFlagSwap;
  ++counters_.field_swaps;
  field_epoch_.fetch_add(1, std::memory_order_acq_rel);  // acknowledged: the old field is no longer read
}

void ServoLoop::Publish() {
  if (config_.wait_when_full) {
    while (!ring_.TryPush(pending_)) {
      if (stop_.load(std::memory_order_acquire)) {
        (void)ring_.Push(pending_);  // stopping: count it as dropped rather than wait
        break;
      }
      Nap();
    }
  } else {
    (void)ring_.Push(pending_);
  }
  counters_.dropped_rows = ring_.dropped();
}

StepResult ServoLoop::Step() {
  if (loop_state_ == LoopState::kFault) return EnterFault(fault_);
  if (const int f = fault_request_.load(std::memory_order_acquire); f != 0)
    return EnterFault(static_cast<FaultCause>(f));
  const std::uint64_t ticks_before = counters_.ticks;
  const StepResult r = Tick(clock_.NowNs(), -1);
  if (counters_.ticks != ticks_before) Publish();
  return r;
}

RunEnd ServoLoop::Run(bool fast, double rate_hz) {
  if (!fast && !(rate_hz >= 1 && rate_hz <= 10000)) {
    WriteZeroForce();
    return RunEnd::kInvalidRate;
  }
  const auto period_ns = fast ? std::int64_t{0} : static_cast<std::int64_t>(std::llround(1e9 / rate_hz));
  RunEnd end = RunEnd::kStopped;
  std::int64_t deadline_ns = clock_.NowNs() + period_ns;  // the first tick, too, wakes from a sleep
  for (;;) {
    if (stop_.load(std::memory_order_acquire)) {
      end = RunEnd::kStopped;
      break;
    }
    std::int64_t wake_latency_ns = -1;
    std::int64_t start_ns = 0;
    if (!fast) {
      clock_.SleepUntilNs(deadline_ns, stop_);
      if (stop_.load(std::memory_order_acquire)) {
        end = RunEnd::kStopped;
        break;
      }
      start_ns = clock_.NowNs();
      wake_latency_ns = start_ns - deadline_ns;
    } else {
      start_ns = clock_.NowNs();
    }
    if (const int f = fault_request_.load(std::memory_order_acquire); f != 0) {
      EnterFault(static_cast<FaultCause>(f));
    } else {
      const std::uint64_t ticks_before = counters_.ticks;
      const StepResult s = Tick(start_ns, wake_latency_ns);
      const bool ticked = counters_.ticks != ticks_before;
      if (ticked && !fast) {
        deadline_ns += period_ns;
        const std::int64_t end_ns = start_ns + pending_.compute_ns;
        if (end_ns > deadline_ns) {
          // Late: keep the grid start + n·period but jump to its first point after now, so
          // missed ticks are skipped instead of run back to back.
          pending_.flags |= kFlagOverrun;
          ++counters_.overruns;
          ++consecutive_overruns_;
          if (consecutive_overruns_ > counters_.max_consecutive_overruns)
            counters_.max_consecutive_overruns = consecutive_overruns_;
          deadline_ns += ((end_ns - deadline_ns) / period_ns + 1) * period_ns;
        } else {
          consecutive_overruns_ = 0;
        }
      }
      if (ticked) Publish();
      if (s == StepResult::kEnded) {
        end = RunEnd::kEnded;
        break;
      }
      if (s == StepResult::kDeviceError) {
        end = RunEnd::kDeviceError;
        break;
      }
      if (s == StepResult::kRunning && config_.overrun_fault_limit != 0 &&
          consecutive_overruns_ >= config_.overrun_fault_limit) {
        EnterFault(FaultCause::kOverruns);
      }
    }
    if (loop_state_ == LoopState::kFault) {
      end = fault_ == FaultCause::kOverruns ? RunEnd::kOverrunFault : RunEnd::kWatchdogFault;
      break;
    }
  }
  WriteZeroForce();  // the last action of every run
  return end;
}

std::span<const LogRow> ServoLoop::rows() const {
  rows_snapshot_.clear();
  rows_snapshot_.reserve(ring_.size());
  ring_.ForEachQueued([&](const TelemetrySample& s) { rows_snapshot_.push_back(s.row); });
  return rows_snapshot_;
}

std::span<const std::int64_t> ServoLoop::tick_ns() const {
  tick_ns_snapshot_.clear();
  tick_ns_snapshot_.reserve(ring_.size());
  ring_.ForEachQueued([&](const TelemetrySample& s) { tick_ns_snapshot_.push_back(s.compute_ns); });
  return tick_ns_snapshot_;
}

}  // namespace palpa::servo
