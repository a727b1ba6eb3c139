// palpad --record / --record-timing: a TelemetrySink on the drain thread (non-RT). The servo loop
// only pushes its TelemetrySample into the wait-free SPSC ring, as for --out; this sink writes
// each drained sample's HIP to a trace (trace::TraceStreamWriter: binary v2 for .ptb, else text
// v2) and, optionally, its timing to a CSV. The loop therefore never waits on the disk. Samples the
// ring dropped (full) show as gaps in the tick numbers and are counted; samples the trace format
// refuses (outside the Falcon workspace, time not increasing) are counted too. Both counts are
// reported after the run, never silent.
//
// Files are written through io::AtomicFile and renamed into place by Commit (after fsync), like
// --out. Header-only: palpad is the only user.
#pragma once

#include <cstdint>
#include <cstdio>
#include <expected>
#include <memory>
#include <optional>
#include <string>
#include <utility>

#include "palpa/io/atomic_file.h"
#include "palpa/record/run_record.h"
#include "palpa/servo/telemetry_drain.h"
#include "palpa/trace/trace.h"

namespace palpa::palpad {

class Recorder final : public servo::TelemetrySink {
 public:
  /// Opens the temporaries (either path may be empty). Error: a sentence naming the path.
  static std::expected<std::unique_ptr<Recorder>, std::string> Open(const std::string& trace_path,
                                                                    const std::string& timing_path,
                                                                    const std::string& comment) {
    std::unique_ptr<Recorder> r(new Recorder);
    if (!trace_path.empty()) {
      auto f = io::AtomicFile::Create(trace_path);
      if (!f) return std::unexpected(f.error());
      r->trace_.emplace(std::move(*f));
      r->trace_path_ = trace_path;
      r->writer_ = std::make_unique<trace::TraceStreamWriter>(r->trace_->file(), trace_path.ends_with(".ptb"), comment);
      if (!r->writer_->Begin()) return std::unexpected("cannot write " + trace_path);
    }
    if (!timing_path.empty()) {
      auto f = io::AtomicFile::Create(timing_path);
      if (!f) return std::unexpected(f.error());
      r->timing_.emplace(std::move(*f));
      r->timing_path_ = timing_path;
      if (!record::WriteTimingHeader(r->timing_->file())) return std::unexpected("cannot write " + timing_path);
    }
    return r;
  }

  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;
  ~Recorder() override = default;

  /// Drain thread.
  void Consume(const servo::TelemetrySample& s) override {
    if (s.tick > next_tick_) gaps_ += s.tick - next_tick_;  // the ring dropped these
    next_tick_ = s.tick + 1;
    ++samples_;
    if (writer_) (void)writer_->Add({s.row.t_s, s.row.hip_m, s.buttons});
    if (timing_ && !timing_failed_) {
      const record::TimingRow row{
          s.tick, s.row.t_s, s.wake_latency_ns, s.compute_ns, record::TotalNs(s.wake_latency_ns, s.compute_ns),
          s.flags};
      if (!record::WriteTimingRow(timing_->file(), row)) timing_failed_ = true;
    }
  }

  /// After the drain stopped. `ring_dropped`: the loop's count (also covers a dropped tail).
  std::expected<void, std::string> Commit(std::uint64_t ring_dropped) {
    ring_dropped_ = ring_dropped;
    if (writer_) {
      if (auto done = writer_->Finish(); !done) return std::unexpected(trace_path_ + ": " + done.error());
      if (auto e = trace_->Commit(); !e) return std::unexpected(e.error());
    }
    if (timing_) {
      if (timing_failed_) return std::unexpected("cannot write " + timing_path_);
      if (auto e = timing_->Commit(); !e) return std::unexpected(e.error());
    }
    return {};
  }

  /// One line for stderr, e.g. "recorded 5000 HIP samples to r.ptb (0 dropped by the full ring, 0 refused)".
  std::string Report() const {
    std::string out;
    const unsigned long long dropped = ring_dropped_ > gaps_ ? ring_dropped_ : gaps_;
    if (writer_)
      out += "palpad: recorded " + std::to_string(writer_->written()) + " HIP samples to " + trace_path_ + " (" +
             std::to_string(dropped) + " dropped by the full ring, " + std::to_string(writer_->refused()) +
             " refused by the trace format)\n";
    if (timing_)
      out += "palpad: recorded the timing of " + std::to_string(samples_) + " ticks to " + timing_path_ + "\n";
    return out;
  }

 private:
  Recorder() = default;

  // Written as <path>.tmp.XXXXXX (io::AtomicFile: checked target, fsync, rename, the temporary
  // registered for the fatal-signal path) and renamed onto <path> by Commit; removed if never committed.
  std::optional<io::AtomicFile> trace_, timing_;
  std::string trace_path_, timing_path_;
  std::unique_ptr<trace::TraceStreamWriter> writer_;
  std::uint64_t next_tick_ = 0, gaps_ = 0, samples_ = 0, ring_dropped_ = 0;
  bool timing_failed_ = false;
};

}  // namespace palpa::palpad
