#include "palpa/servo/report.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdarg>
#include <cstring>
#include <utility>
#include <vector>

namespace palpa::servo {
namespace {

[[gnu::format(printf, 1, 2)]] std::string Printf(const char* fmt, ...) {
  char buf[512];
  va_list args;
  va_start(args, fmt);
  const int n = std::vsnprintf(buf, sizeof buf, fmt, args);
  va_end(args);
  if (n < 0) return {};
  return std::string(buf, std::min(static_cast<std::size_t>(n), sizeof buf - 1));
}

std::string ErrnoMessage(const char* what, const std::string& path) {
  return Printf("%s %s: %s", what, path.c_str(), std::strerror(errno));
}

std::string DirectoryOf(const std::string& path) {
  const auto slash = path.rfind('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

}  // namespace

bool WriteCsv(std::FILE* out, std::span<const LogRow> rows) {
  if (std::fprintf(out, "%.*s\n", static_cast<int>(kCsvHeader.size()), kCsvHeader.data()) < 0) return false;
  for (const LogRow& r : rows) {
    const int n = std::fprintf(out, "%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.9g,%.9g,%.9g,%d\n", r.t_s, r.hip_m[0],
                               r.hip_m[1], r.hip_m[2], r.proxy_m[0], r.proxy_m[1], r.proxy_m[2], r.force_n[0],
                               r.force_n[1], r.force_n[2], r.contact ? 1 : 0);
    if (n < 0) return false;
  }
  return std::ferror(out) == 0;
}

std::expected<AtomicFile, std::string> AtomicFile::Create(const std::string& path) {
  std::string temp = path + ".tmp.XXXXXX";
  const int fd = mkstemp(temp.data());
  if (fd < 0) return std::unexpected(ErrnoMessage("cannot create a temporary file for", path));
  // mkstemp makes the file 0600; give the result the mode an ordinary create would.
  const mode_t mask = umask(0);
  umask(mask);
  (void)fchmod(fd, static_cast<mode_t>(0666) & ~mask);
  std::FILE* f = fdopen(fd, "w");
  if (f == nullptr) {
    std::string message = ErrnoMessage("cannot open", temp);
    close(fd);
    unlink(temp.c_str());
    return std::unexpected(std::move(message));
  }
  return AtomicFile(path, std::move(temp), f);
}

AtomicFile::AtomicFile(AtomicFile&& other) noexcept
    : path_(std::move(other.path_)),
      temp_path_(std::move(other.temp_path_)),
      file_(std::exchange(other.file_, nullptr)) {}

AtomicFile::~AtomicFile() {
  if (file_ != nullptr) {
    std::fclose(file_);
    unlink(temp_path_.c_str());
  }
}

std::expected<void, std::string> AtomicFile::Commit() {
  if (file_ == nullptr) return std::unexpected("already committed: " + path_);
  std::FILE* f = std::exchange(file_, nullptr);
  bool ok = std::fflush(f) == 0 && std::ferror(f) == 0;
  std::string message = ok ? std::string() : ErrnoMessage("cannot write", temp_path_);
  if (ok && fsync(fileno(f)) != 0) {
    ok = false;
    message = ErrnoMessage("cannot fsync", temp_path_);
  }
  if (std::fclose(f) != 0 && ok) {
    ok = false;
    message = ErrnoMessage("cannot close", temp_path_);
  }
  if (ok && std::rename(temp_path_.c_str(), path_.c_str()) != 0) {
    ok = false;
    message = ErrnoMessage("cannot rename the temporary file onto", path_);
  }
  if (!ok) {
    unlink(temp_path_.c_str());
    return std::unexpected(std::move(message));
  }
  // Make the rename itself durable. Failing here leaves a complete file, so it is not an error.
  const int dir = open(DirectoryOf(path_).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir >= 0) {
    (void)fsync(dir);
    close(dir);
  }
  return {};
}

std::expected<void, std::string> WriteCsvAtomic(const std::string& path, std::span<const LogRow> rows) {
  auto file = AtomicFile::Create(path);
  if (!file) return std::unexpected(std::move(file.error()));
  if (!WriteCsv(file->file(), rows)) return std::unexpected(ErrnoMessage("cannot write", path));
  return file->Commit();
}

std::int64_t PercentileNs(std::span<const std::int64_t> ns, double q) {
  if (ns.empty()) return 0;
  std::vector<std::int64_t> copy(ns.begin(), ns.end());
  // Nearest rank: the smallest value with at least q·n values ≤ it.
  const double rank = std::ceil(std::clamp(q, 0.0, 1.0) * static_cast<double>(copy.size()));
  std::size_t index = rank < 1 ? 0 : static_cast<std::size_t>(rank) - 1;
  index = std::min(index, copy.size() - 1);
  std::nth_element(copy.begin(), copy.begin() + static_cast<std::ptrdiff_t>(index), copy.end());
  return copy[index];
}

ServoSummary Summarize(const ServoLoop& loop, bool fast, double rate_hz) {
  const ServoCounters& c = loop.counters();
  ServoSummary s;
  s.ticks = c.ticks;
  s.contact_ticks = c.contact_ticks;
  s.max_force_n = c.max_force_n;
  s.max_penetration_mm = c.max_penetration_m * 1e3;
  const std::span<const std::int64_t> ns = loop.tick_ns();
  if (!ns.empty()) {
    // Upper median: element n/2 of the sorted durations.
    std::vector<std::int64_t> copy(ns.begin(), ns.end());
    const auto mid = copy.begin() + static_cast<std::ptrdiff_t>(copy.size() / 2);
    std::nth_element(copy.begin(), mid, copy.end());
    s.median_tick_ns = *mid;
  }
  s.p99_tick_ns = PercentileNs(ns, 0.99);
  s.force_clamps = c.force_clamps;
  s.device_errors = c.device_errors;
  s.overruns = c.overruns;
  s.dropped_rows = c.dropped_rows;
  s.rate_hz = rate_hz;
  s.fast = fast;
  return s;
}

std::string SummaryText(const ServoSummary& s) {
  std::string out;
  out += Printf("ticks: %llu\n", static_cast<unsigned long long>(s.ticks));
  out += Printf("ticks in contact: %llu\n", static_cast<unsigned long long>(s.contact_ticks));
  out += Printf("max force (N): %.4f\n", s.max_force_n);
  out += Printf("max penetration (mm): %.4f\n", s.max_penetration_mm);
  out += Printf("median tick (ns): %lld\n", static_cast<long long>(s.median_tick_ns));
  out += Printf("p99 tick (ns): %lld\n", static_cast<long long>(s.p99_tick_ns));
  out += Printf("force clamps: %llu\n", static_cast<unsigned long long>(s.force_clamps));
  out += Printf("device errors: %llu\n", static_cast<unsigned long long>(s.device_errors));
  out += Printf("overruns: %llu\n", static_cast<unsigned long long>(s.overruns));
  out += Printf("dropped rows: %llu\n", static_cast<unsigned long long>(s.dropped_rows));
  out += s.fast ? std::string("mode: fast\n") : Printf("mode: paced at %g Hz\n", s.rate_hz);
  return out;
}

std::string SummaryJson(const ServoSummary& s) {
  // %.17g round-trips a double; the values are finite by construction.
  return Printf(
      "{\"ticks\": %llu, \"contact_ticks\": %llu, \"max_force_n\": %.17g, \"max_penetration_mm\": %.17g, "
      "\"median_tick_ns\": %lld, \"p99_tick_ns\": %lld, \"force_clamps\": %llu, \"device_errors\": %llu, "
      "\"overruns\": %llu, \"dropped_rows\": %llu, \"rate_hz\": %.17g, \"fast\": %s}\n",
      static_cast<unsigned long long>(s.ticks), static_cast<unsigned long long>(s.contact_ticks), s.max_force_n,
      s.max_penetration_mm, static_cast<long long>(s.median_tick_ns), static_cast<long long>(s.p99_tick_ns),
      static_cast<unsigned long long>(s.force_clamps), static_cast<unsigned long long>(s.device_errors),
      static_cast<unsigned long long>(s.overruns), static_cast<unsigned long long>(s.dropped_rows), s.rate_hz,
      s.fast ? "true" : "false");
}

}  // namespace palpa::servo
