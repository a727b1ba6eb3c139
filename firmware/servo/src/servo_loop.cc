#include "palpa/servo/servo_loop.h"

#include <cerrno>
#include <cmath>
#include <ctime>

namespace palpa::servo {
namespace {

constexpr std::int64_t kNsPerS = 1'000'000'000;

// CLOCK_MONOTONIC through the vDSO: no system call on Linux x86-64/aarch64.
std::int64_t NowNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t{ts.tv_sec} * kNsPerS + ts.tv_nsec;
}

void SleepUntil(std::int64_t deadline_ns, const std::atomic<bool>& stop) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(deadline_ns / kNsPerS);
  ts.tv_nsec = static_cast<long>(deadline_ns % kNsPerS);
  // A signal (SIGINT/SIGTERM) interrupts the sleep; the caller then sees the stop flag.
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    if (stop.load(std::memory_order_acquire)) return;
  }
}

}  // namespace

ServoLoop::ServoLoop(const blob::FieldView& field, const proxy::ProxyParams& params, device::HapticDevice& device,
                     std::size_t log_capacity, const std::atomic<bool>& stop)
    : sampler_(field),
      params_(params),
      frame_(proxy::GridFrame::Of(field)),
      device_(device),
      stop_(stop),
      rows_(log_capacity),  // value-initialised: every page is touched now, not in the loop
      tick_ns_(log_capacity) {}

void ServoLoop::WriteZeroForce() {
  if (device_.Write({0.0, 0.0, 0.0}) == device::IoStatus::kError) ++counters_.device_errors;
}

StepResult ServoLoop::Step() {
  const std::int64_t start_ns = NowNs();
  device::HipReading reading;
  switch (device_.Read(reading)) {
    case device::IoStatus::kOk:
      break;
    case device::IoStatus::kEnd:
      WriteZeroForce();
      return StepResult::kEnded;
    case device::IoStatus::kError:
      ++counters_.device_errors;
      WriteZeroForce();
      return StepResult::kDeviceError;
  }

  const proxy::TickResult r = proxy::ProxyTick(sampler_, params_, state_, frame_.ToGrid(reading.hip_m));
  // Q16.16 → double is exact (|raw| < 2^31 fits a 53-bit mantissa).
  const std::array<double, 3> force_n = {r.force[0].value.ToDouble(), r.force[1].value.ToDouble(),
                                         r.force[2].value.ToDouble()};
  const device::IoStatus write_status = device_.Write(force_n);
  const std::int64_t end_ns = NowNs();

  ++counters_.ticks;
  if (r.contact) {
    ++counters_.contact_ticks;
    const double penetration_m = static_cast<double>(r.penetration_q16) / 65536.0 * frame_.voxel_m;
    if (penetration_m > counters_.max_penetration_m) counters_.max_penetration_m = penetration_m;
  }
  if (r.clamped) ++counters_.force_clamps;
  const double f = std::sqrt(force_n[0] * force_n[0] + force_n[1] * force_n[1] + force_n[2] * force_n[2]);
  if (f > counters_.max_force_n) counters_.max_force_n = f;

  if (row_count_ < rows_.size()) {
    LogRow& row = rows_[row_count_];
    row.t_s = reading.t_s;
    row.hip_m = reading.hip_m;
    row.proxy_m = frame_.ToMetres(r.proxy);
    row.force_n = force_n;
    row.contact = r.contact;
    tick_ns_[row_count_] = end_ns - start_ns;
    ++row_count_;
  } else {
    ++counters_.dropped_rows;  // never grow in the loop
  }

  switch (write_status) {
    case device::IoStatus::kOk:
      return StepResult::kRunning;
    case device::IoStatus::kEnd:
      WriteZeroForce();
      return StepResult::kEnded;
    case device::IoStatus::kError:
      break;
  }
  ++counters_.device_errors;
  WriteZeroForce();
  return StepResult::kDeviceError;
}

RunEnd ServoLoop::Run(bool fast, double rate_hz) {
  if (!fast && !(rate_hz >= 1 && rate_hz <= 10000)) {
    WriteZeroForce();
    return RunEnd::kInvalidRate;
  }
  RunEnd end = RunEnd::kStopped;
  const auto period_ns = fast ? std::int64_t{0} : static_cast<std::int64_t>(std::llround(1e9 / rate_hz));
  std::int64_t deadline_ns = NowNs();
  for (;;) {
    if (stop_.load(std::memory_order_acquire)) {
      end = RunEnd::kStopped;
      break;
    }
    const StepResult s = Step();
    if (s == StepResult::kEnded) {
      end = RunEnd::kEnded;
      break;
    }
    if (s == StepResult::kDeviceError) {
      end = RunEnd::kDeviceError;
      break;
    }
    if (fast) continue;
    deadline_ns += period_ns;
    const std::int64_t now_ns = NowNs();
    if (now_ns > deadline_ns) {
      // Late: keep the grid start + n·period but jump to its next point after now, so missed
      // ticks are skipped instead of run back to back.
      ++counters_.overruns;
      deadline_ns += ((now_ns - deadline_ns) / period_ns + 1) * period_ns;
    }
    SleepUntil(deadline_ns, stop_);
  }
  WriteZeroForce();  // the last action of every run
  return end;
}

}  // namespace palpa::servo
