// palpad --record / --record-timing: a TelemetrySink on the drain thread (non-RT). The servo loop
// only pushes its TelemetrySample into the wait-free SPSC ring, as for --out; this sink writes
// each drained sample's HIP to a trace (trace::TraceStreamWriter: binary v2 for .ptb, else text
// v2) and, optionally, its timing to a CSV. The loop therefore never waits on the disk. Samples the
// ring dropped (full) show as gaps in the tick numbers and are counted; samples the trace format
// refuses (outside the Falcon workspace, time not increasing) are counted too. Both counts are
// reported after the run, never silent.
//
// Files are written under a temporary name and renamed into place by Commit (after fsync), like
// --out. Header-only: palpad is the only user.
#pragma once

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <expected>
#include <memory>
#include <string>
#include <utility>

#include "palpa/io/file_safety.h"
#include "palpa/rt/temp_registry.h"
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
      if (auto e = r->trace_.Open(trace_path); !e.empty()) return std::unexpected(e);
      r->writer_ = std::make_unique<trace::TraceStreamWriter>(r->trace_.file, trace_path.ends_with(".ptb"), comment);
      if (!r->writer_->Begin()) return std::unexpected("cannot write " + trace_path);
    }
    if (!timing_path.empty()) {
      if (auto e = r->timing_.Open(timing_path); !e.empty()) return std::unexpected(e);
      if (std::fputs("tick,t_s,wake_ns,compute_ns,total_ns,flags\n", r->timing_.file) < 0)
        return std::unexpected("cannot write " + timing_path);
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
    if (timing_.file != nullptr && !timing_failed_) {
      // total: deadline to force written (paced), or the compute time alone (fast, no deadline).
      const std::int64_t total = s.wake_latency_ns >= 0 ? s.wake_latency_ns + s.compute_ns : s.compute_ns;
      if (std::fprintf(timing_.file, "%llu,%.9f,%lld,%lld,%lld,%u\n", static_cast<unsigned long long>(s.tick),
                       s.row.t_s, static_cast<long long>(s.wake_latency_ns), static_cast<long long>(s.compute_ns),
                       static_cast<long long>(total), s.flags) < 0)
        timing_failed_ = true;
    }
  }

  /// After the drain stopped. `ring_dropped`: the loop's count (also covers a dropped tail).
  std::expected<void, std::string> Commit(std::uint64_t ring_dropped) {
    ring_dropped_ = ring_dropped;
    if (writer_) {
      if (auto done = writer_->Finish(); !done) return std::unexpected(trace_.path + ": " + done.error());
      if (auto e = trace_.Commit(); !e.empty()) return std::unexpected(e);
    }
    if (timing_.file != nullptr) {
      if (timing_failed_) return std::unexpected("cannot write " + timing_.path);
      if (auto e = timing_.Commit(); !e.empty()) return std::unexpected(e);
    }
    return {};
  }

  /// One line for stderr, e.g. "recorded 5000 HIP samples to r.ptb (0 dropped by the full ring, 0 refused)".
  std::string Report() const {
    std::string out;
    const unsigned long long dropped = ring_dropped_ > gaps_ ? ring_dropped_ : gaps_;
    if (writer_)
      out += "palpad: recorded " + std::to_string(writer_->written()) + " HIP samples to " + trace_.path + " (" +
             std::to_string(dropped) + " dropped by the full ring, " + std::to_string(writer_->refused()) +
             " refused by the trace format)\n";
    if (timing_.file != nullptr || timing_.committed)
      out += "palpad: recorded the timing of " + std::to_string(samples_) + " ticks to " + timing_.path + "\n";
    return out;
  }

 private:
  Recorder() = default;

  // A file written as <path>.tmp.XXXXXX ("w+b": the binary trace reads itself back for its CRC)
  // and renamed onto <path> by Commit; removed if never committed.
  struct TempFile {
    std::string path, temp;
    std::FILE* file = nullptr;
    bool committed = false;
    int slot = -1;  // rt::RegisterTempPath slot of `temp`
    std::string Open(const std::string& p) {
      path = p;
      if (auto ok = io::CheckOutputTarget(p); !ok) return ok.error().message;  // never over a device (issue 18)
      temp = p + ".tmp.XXXXXX";
      const int fd = mkstemp(temp.data());
      if (fd < 0) return "cannot create a temporary file for " + p + ": " + std::strerror(errno);
      const mode_t mask = umask(0);
      umask(mask);
      (void)fchmod(fd, static_cast<mode_t>(0666) & ~mask);
      file = fdopen(fd, "w+b");
      if (file == nullptr) {
        close(fd);
        unlink(temp.c_str());
        return "cannot open " + temp;
      }
      slot = rt::RegisterTempPath(temp.c_str());  // a fatal signal unlinks it
      return {};
    }
    std::string Commit() {
      const bool ok = std::fflush(file) == 0 && fsync(fileno(file)) == 0;
      const bool closed = std::fclose(file) == 0;
      file = nullptr;
      const bool renamed = ok && closed && std::rename(temp.c_str(), path.c_str()) == 0;
      if (!renamed) unlink(temp.c_str());
      rt::UnregisterTempPath(std::exchange(slot, -1));
      if (!renamed) return "cannot write " + path + ": " + std::strerror(errno);
      committed = true;
      return {};
    }
    ~TempFile() {
      if (file != nullptr) {
        std::fclose(file);
        unlink(temp.c_str());
      }
      rt::UnregisterTempPath(slot);
    }
  };

  TempFile trace_, timing_;
  std::unique_ptr<trace::TraceStreamWriter> writer_;
  std::uint64_t next_tick_ = 0, gaps_ = 0, samples_ = 0, ring_dropped_ = 0;
  bool timing_failed_ = false;
};

}  // namespace palpa::palpad
