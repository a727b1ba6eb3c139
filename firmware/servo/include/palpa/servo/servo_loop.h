// The servo loop: read the HIP, run the proxy (paper §3.3 eq. 9) and force (§3.4 eq. 10), write
// the force — once per tick, on one thread.
//
// Per tick: toggle the tick line (if any) → read the e-stop line (if any) → Read the device →
// proxy + force (zero while the e-stop is asserted, ramped in after its release) → Write → time
// stamps into fixed histograms → one TelemetrySample into the SPSC ring. Nothing else leaves the
// loop: a non-RT thread drains the ring (TelemetryDrain) to the output CSV and the status.
//
// Pacing (Run, paced): absolute deadlines start + n·period with clock_nanosleep(TIMER_ABSTIME).
// Wake-up latency = wake time − deadline; compute time = wake-up to after the force write.
// Overrun policy: a tick that ends after the next deadline is an overrun; the loop then skips to
// the first deadline still in the future (missed ticks are never run back to back). After
// `overrun_fault_limit` consecutive overruns the loop writes zero force, latches the fault state
// and Run returns kOverrunFault.
//
// E-stop: asserted (the configured level, or a failed read) → zero force in the same tick, the
// proxy is not run. Released only after `estop_release_ticks` consecutive released reads
// (debounce); then the proxy restarts at the HIP (ProxyState reset) and the force ramps from 0 to
// 100 % over `ramp_ticks`. Assertion is never debounced: stopping must not wait.
//
// Field swap (issue 7, docs/upload.md): another thread prepares a ServoField (verified blob,
// sampler, proxy parameters) and offers it with OfferField (one atomic store). At the start of the
// next tick the loop takes it with one atomic exchange, restarts the proxy in the new field (seeded
// on the surface nearest the HIP, see SeedProxy) and cross-fades the force linearly from the last
// force written in the old field to the new field's over `swap_ramp_ticks`; then it increments
// field_epoch() (the acknowledgement: from then on the old field's memory is no longer read). The
// loop never waits for, locks or allocates anything here.
//
// Watchdog hooks: tick_sequence() is odd while a tick runs; a watchdog thread (Watchdog) that sees
// it stuck calls RequestFault, and the loop writes zero force as soon as the device call returns.
//
// Thread/RT rules: construct, inspect and report on any thread while the loop is not running
// (non-RT: the constructor allocates the ring and histograms). Step() and Run() belong to the
// servo thread. Inside them there is no allocation, lock or exception, and the system calls are
// the device's and the GPIO lines' transfers, the clock read (vDSO) and, paced, clock_nanosleep;
// tests/firmware/alloc_free_test.cc and rt_test.cc check it. Only the stop flag, RequestFault and
// the ring's consumer side are touched by other threads during a run.
#pragma once

#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <type_traits>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/device/haptic_device.h"
#include "palpa/gpio/gpio.h"
#include "palpa/proxy/proxy.h"
#include "palpa/record/run_record.h"
#include "palpa/rt/clock.h"
#include "palpa/rt/histogram.h"
#include "palpa/rt/spsc_ring.h"
#include "palpa/sampler/trilinear.h"

namespace palpa::servo {

// Set from signal handlers and read by the loop: must be a plain lock-free atomic.
static_assert(std::atomic<bool>::is_always_lock_free);

/// One tick as the output CSV row (palpa/record/run_record.h: the run record's one definition).
using record::LogRow;

/// TelemetrySample::flags bits (palpa/record/run_record.h).
using record::kFlagClamped;
using record::kFlagEstop;
using record::kFlagGpioError;
using record::kFlagOverrun;
using record::kFlagRamp;
using record::kFlagSwap;
using record::kFlagSwapRamp;
using record::TelemetryFlag;

/// What one tick sends through the ring.
struct TelemetrySample {
  std::uint64_t tick = 0;             ///< 0-based tick index
  LogRow row;                         ///< the CSV row
  std::int64_t wake_latency_ns = -1;  ///< paced: wake time − deadline, ns; −1 when not paced
  std::int64_t compute_ns = 0;        ///< wake-up (or Step start) to after the force write, ns
  std::uint32_t flags = 0;            ///< TelemetryFlag bits
  std::uint8_t buttons = 0;           ///< the device's buttons this tick (HipReading::buttons), for --record
};
static_assert(std::is_trivially_copyable_v<TelemetrySample>);

/// Telemetry ring type: drops the newest sample when full (counted), never blocks the loop.
using TelemetryRing = rt::SpscRing<TelemetrySample, rt::OnFull::kDropNewest>;

/// Wake-up latency: 1 µs bins (cyclictest's unit) up to 20 ms, the worst seen on the dev VM ×2.
using WakeLatencyHistogram = rt::LinearHistogram<1000, 20000>;
/// Compute time: 10 ns bins up to 500 µs (a tick takes ~1-10 µs natively, ~20× that under qemu).
using ComputeHistogram = rt::LinearHistogram<10, 50000>;

/// The loop's state machine.
enum class LoopState {
  kRunning,  ///< rendering forces
  kEstop,    ///< e-stop asserted (or its release not yet debounced): zero force
  kRamp,     ///< released: the force ramps in
  kFault,    ///< latched: zero force written, Run returns
};
const char* LoopStateName(LoopState s);

/// Why the fault state was entered.
enum class FaultCause {
  kNone,
  kOverruns,  ///< overrun_fault_limit consecutive overruns
  kWatchdog,  ///< RequestFault: a tick did not complete in time (device stalled)
};
const char* FaultCauseName(FaultCause c);

struct ServoConfig {
  /// Telemetry ring capacity, samples. With no consumer the ring keeps the first `capacity` ticks.
  std::size_t telemetry_capacity = 1u << 16;
  /// false (RT): a full ring drops the sample (counted). true (lockstep replay only, not RT): the
  /// loop waits for room, so the output is complete and deterministic; needs a running drain.
  bool wait_when_full = false;
  /// Consecutive overruns that latch the fault state; 0: never.
  std::uint32_t overrun_fault_limit = 10;
  /// Time source; nullptr: rt::MonotonicClock().
  rt::Clock* clock = nullptr;
  /// E-stop input; nullptr: none.
  gpio::DigitalInput* estop = nullptr;
  bool estop_active_high = true;          ///< the level that asserts the e-stop
  std::uint32_t estop_release_ticks = 5;  ///< consecutive released reads before the release counts (≥ 1)
  std::uint32_t ramp_ticks = 500;         ///< ticks for the force to ramp 0 → 100 % after a release; 0: at once
  std::uint32_t swap_ramp_ticks = 50;     ///< ticks for the force to ramp 0 → 100 % after a field swap; 0: at once
  /// Output toggled at the start of every tick; nullptr: none.
  gpio::DigitalOutput* tick_line = nullptr;
};

/// Counters the servo thread writes (house style §5); read them after the run.
struct ServoCounters {
  std::uint64_t ticks = 0;          ///< completed ticks (read, proxy or e-stop, write)
  std::uint64_t contact_ticks = 0;  ///< ticks with contact
  std::uint64_t force_clamps = 0;   ///< ticks whose |f| hit max_force
  std::uint64_t device_errors = 0;  ///< failed reads/writes (each ends the run)
  std::uint64_t dropped_rows = 0;   ///< telemetry samples dropped because the ring was full
  std::uint64_t overruns = 0;       ///< paced: ticks that ended after the next deadline
  std::uint64_t max_consecutive_overruns = 0;
  std::uint64_t estop_events = 0;  ///< e-stop assertions (released → asserted)
  std::uint64_t estop_ticks = 0;   ///< ticks with the e-stop asserted (zero force)
  std::uint64_t gpio_errors = 0;   ///< failed e-stop reads (treated as asserted) and tick-line writes
  double max_force_n = 0;          ///< max |f| written, N
  double max_penetration_m = 0;    ///< max |X_p − X_h| in contact, m
  std::uint64_t field_swaps = 0;   ///< fields taken from OfferField
  std::uint64_t swap_seeds = 0;    ///< swaps whose proxy was seeded on the new surface (else restarted at the HIP)
};
static_assert(std::is_trivially_copyable_v<ServoCounters>);

/// Outcome of one Step().
enum class StepResult {
  kRunning,      ///< tick done, keep going
  kEnded,        ///< the device reported kEnd (replay over); zero force written
  kDeviceError,  ///< a transfer failed; counted, zero force written
  kFault,        ///< the fault state is latched; zero force written
};

/// Why Run() returned.
enum class RunEnd {
  kEnded,          ///< the device ran out (replay finished)
  kStopped,        ///< the stop flag was set (SIGINT/SIGTERM)
  kDeviceError,    ///< a device transfer failed
  kInvalidRate,    ///< paced mode with rate_hz outside [1, 10000]; nothing ran
  kOverrunFault,   ///< overrun_fault_limit consecutive overruns
  kWatchdogFault,  ///< the watchdog found a tick that did not complete
};
const char* RunEndName(RunEnd e);

/// A field ready for the loop: the sampler over a verified view (its Lipschitz scan done), the grid
/// frame and the proxy parameters for its voxel size. Built non-RT (O(grid) scan); the blob buffer
/// the view reads must outlive it. Immutable once built, so the loop may read it from another
/// thread's construction after the release/acquire hand-over of OfferField.
struct ServoField {
  ServoField(const blob::FieldView& field, const proxy::ProxyParams& proxy_params, std::uint64_t bytes = 0)
      : sampler(field),
        frame(proxy::GridFrame::Of(field)),
        params(proxy_params),
        crc32c(field.crc32c),
        dims(field.dims),
        blob_bytes(bytes) {}
  sampler::TrilinearSampler sampler;
  proxy::GridFrame frame;
  proxy::ProxyParams params;
  std::uint32_t crc32c = 0;            ///< the blob's CRC-32C
  std::array<std::int32_t, 3> dims{};  ///< nodes per axis
  std::uint64_t blob_bytes = 0;        ///< blob size (reporting)
};

class ServoLoop {
 public:
  /// `field` must be verified (blob::Verify) and its buffer must outlive the loop; `params` from
  /// proxy::MakeProxyParams for this field's voxel size; `device`, the clock and the GPIO lines
  /// outlive the loop. `stop` is polled once per tick. Non-RT: allocates and touches the ring and
  /// the histograms.
  ServoLoop(const blob::FieldView& field, const proxy::ProxyParams& params, device::HapticDevice& device,
            const ServoConfig& config, const std::atomic<bool>& stop);
  /// A plain replay loop: ServoConfig's defaults with a ring of `telemetry_capacity` samples
  /// (undrained, it keeps the first `telemetry_capacity` ticks, rows(), and counts the rest as
  /// dropped) and no overrun fault (overrun_fault_limit 0), no GPIO.
  ServoLoop(const blob::FieldView& field, const proxy::ProxyParams& params, device::HapticDevice& device,
            std::size_t telemetry_capacity, const std::atomic<bool>& stop);

  ServoLoop(const ServoLoop&) = delete;
  ServoLoop& operator=(const ServoLoop&) = delete;

  /// One tick now (no pacing; the wake-up latency is not measured). On kEnd, an error or a latched
  /// fault: zero force written. RT-safe as described above.
  StepResult Step();

  /// Ticks until the device ends, a transfer fails, a fault latches or `stop` is set. fast: back
  /// to back (lockstep, deterministic output); paced: see the file comment. rate_hz in [1, 10000]
  /// (checked only when paced). Always ends by writing zero force. Servo thread; RT-safe.
  RunEnd Run(bool fast, double rate_hz);

  /// Any thread (the watchdog): latch the fault state; the servo thread writes zero force at its
  /// next check (after the device call in progress returns). Wait-free.
  void RequestFault(FaultCause cause) noexcept;
  /// Incremented at the start and at the end of every tick: odd while a tick runs. Any thread.
  std::uint64_t tick_sequence() const { return tick_seq_.load(std::memory_order_acquire); }

  const ServoCounters& counters() const { return counters_; }
  LoopState state() const { return loop_state_; }
  FaultCause fault() const { return fault_; }
  const WakeLatencyHistogram& wake_latency() const { return *wake_; }
  const ComputeHistogram& compute_time() const { return *compute_; }
  /// The ring's consumer side belongs to one drain thread (or, after the run, to the caller).
  TelemetryRing& telemetry() { return ring_; }
  /// Memory the loop touches after start (ring, histograms), for rt::PrepareRealtimeThread.
  std::array<std::span<const std::byte>, 3> buffers() const;

  /// Non-RT, consumer side, after the run when nothing drains the ring: the queued (undrained)
  /// rows, oldest first — without a drain, the first telemetry_capacity ticks. The span views a
  /// snapshot the loop keeps; it stays valid until the next rows() call or the loop's end.
  std::span<const LogRow> rows() const;
  /// As rows(): each queued tick's compute time, ns (its own snapshot).
  std::span<const std::int64_t> tick_ns() const;

  /// Any thread: offers `field` to the loop, which takes it at the start of its next tick (one
  /// atomic exchange) and then increments field_epoch(). `field` must stay alive and unchanged
  /// while offered and while in use. Returns the previously offered field that the loop had not
  /// taken yet (withdrawn), or nullptr. Wait-free.
  const ServoField* OfferField(const ServoField* field) noexcept {
    return offered_.exchange(field, std::memory_order_acq_rel);
  }
  /// Fields taken so far; once it passes the value seen before OfferField, the previous field's
  /// memory is no longer read by the loop. Any thread, acquire.
  std::uint64_t field_epoch() const { return field_epoch_.load(std::memory_order_acquire); }
  /// The loop's field (servo thread, or any thread after field_epoch() acknowledged it).
  const ServoField& field() const { return *field_; }

  const proxy::ProxyState& proxy_state() const { return state_; }
  const proxy::GridFrame& frame() const { return frame_; }

 private:
  StepResult Tick(std::int64_t start_ns, std::int64_t wake_latency_ns);
  bool ReadEstop(std::uint32_t& flags);
  void Publish();
  void WriteZeroForce();
  StepResult EnterFault(FaultCause cause);
  void TakeOfferedField(const device::HipReading& reading, std::uint32_t& flags);

  ServoField initial_;                               // the start-up field
  const ServoField* field_ = &initial_;              // the field in use (servo thread)
  std::atomic<const ServoField*> offered_{nullptr};  // OfferField → the next tick
  std::atomic<std::uint64_t> field_epoch_{0};
  std::uint32_t swap_ramp_tick_ = 0;  // ticks since the last swap, while ramping
  bool swap_ramping_ = false;
  std::array<double, 3> swap_hold_n_{};   // the force written just before the swap, N
  std::array<double, 3> last_force_n_{};  // the last force written, N
  proxy::GridFrame frame_;
  proxy::ProxyState state_;
  device::HapticDevice& device_;
  ServoConfig config_;
  rt::Clock& clock_;
  const std::atomic<bool>& stop_;
  TelemetryRing ring_;
  std::unique_ptr<WakeLatencyHistogram> wake_;  // heap: 80 KB and 200 KB, allocated once
  std::unique_ptr<ComputeHistogram> compute_;
  TelemetrySample pending_;  // the last tick's sample, published by Publish()
  ServoCounters counters_;
  LoopState loop_state_ = LoopState::kRunning;
  FaultCause fault_ = FaultCause::kNone;
  std::atomic<int> fault_request_{0};  // a FaultCause, set by RequestFault
  std::atomic<std::uint64_t> tick_seq_{0};
  std::uint64_t tick_index_ = 0;
  std::uint64_t consecutive_overruns_ = 0;
  std::uint32_t release_count_ = 0;  // consecutive released e-stop reads
  std::uint32_t ramp_tick_ = 0;
  bool tick_level_ = false;
  mutable std::vector<LogRow> rows_snapshot_;  // rows(), tick_ns(): non-RT, after the run
  mutable std::vector<std::int64_t> tick_ns_snapshot_;
};

}  // namespace palpa::servo
