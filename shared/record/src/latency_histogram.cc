#include "palpa/record/latency_histogram.h"

#include <cerrno>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "palpa/io/file_safety.h"

namespace palpa::record {
namespace {

[[gnu::format(printf, 2, 3)]] void Append(std::string& out, const char* fmt, ...) {
  char buf[128];
  va_list args;
  va_start(args, fmt);
  const int n = std::vsnprintf(buf, sizeof buf, fmt, args);
  va_end(args);
  if (n > 0) out.append(buf, std::min(static_cast<std::size_t>(n), sizeof buf - 1));
}

std::string_view Trim(std::string_view s) {
  const auto b = s.find_first_not_of(" \t");
  const auto e = s.find_last_not_of(" \t\r");
  return b == std::string_view::npos ? std::string_view() : s.substr(b, e - b + 1);
}

constexpr std::size_t kMaxLine = 4096;
constexpr unsigned long long kMaxBin = 10'000'000;  // 10 s of 1 µs bins: far beyond any tracked range

}  // namespace

std::string FormatLatencyHistogram(std::span<const std::uint32_t> bins, const LatencyTotals& t,
                                   std::span<const PalpadLine> lines) {
  std::size_t last = 0;
  for (std::size_t i = 0; i < bins.size(); ++i)
    if (bins[i] != 0) last = i;
  std::string out = "# palpad wake-up latency histogram, 1 us bins (cyclictest -h layout)\n";
  for (std::size_t i = 0; i < bins.size() && i <= last; ++i) Append(out, "%06zu %06u\n", i, bins[i]);
  Append(out, "# Total: %09llu\n", static_cast<unsigned long long>(t.count));
  Append(out, "# Min Latencies: %05lld\n", static_cast<long long>(t.min_ns / 1000));
  Append(out, "# Avg Latencies: %05lld\n", static_cast<long long>(std::llround(t.mean_ns / 1000)));
  Append(out, "# Max Latencies: %05lld\n", static_cast<long long>(t.max_ns / 1000));
  Append(out, "# Histogram Overflows: %05llu\n", static_cast<unsigned long long>(t.overflow));
  Append(out, "# palpad max_ns: %lld\n", static_cast<long long>(t.max_ns));
  for (const auto& [key, value] : lines) out += "# palpad " + key + ": " + value + "\n";
  return out;
}

std::int64_t LatencyHistogram::MinNs() const {
  for (std::size_t i = 0; i < bins.size(); ++i)
    if (bins[i] != 0) return static_cast<std::int64_t>(i) * 1000;
  return max_ns;
}

std::string LatencyHistogram::Palpad(std::string_view key) const {
  for (const auto& [k, v] : palpad)
    if (k == key) return v;
  return "?";
}

void LatencyHistogram::Merge(const LatencyHistogram& other) {
  if (bins.size() < other.bins.size()) bins.resize(other.bins.size(), 0);
  for (std::size_t i = 0; i < other.bins.size(); ++i) bins[i] += other.bins[i];
  overflow += other.overflow;
  count += other.count;
  max_ns = std::max(max_ns, other.max_ns);
}

std::expected<LatencyHistogram, std::string> ReadLatencyHistogram(const std::string& path) {
  auto reader = io::LineReader::Open(path, kMaxLine, "latency histogram");
  if (!reader) return std::unexpected(std::move(reader.error().message));
  LatencyHistogram h;
  std::int64_t max_us = -1;
  std::string max_ns;  // "# palpad max_ns", exact
  std::string_view line;
  for (;;) {
    const io::LineReader::Status status = reader->Next(line);
    if (status == io::LineReader::Status::kEnd) break;
    const std::string where = path + ":" + std::to_string(reader->line_number());
    if (status == io::LineReader::Status::kTooLong)
      return std::unexpected(where + ": line longer than " + io::FormatBytes(kMaxLine));
    if (status == io::LineReader::Status::kError)
      return std::unexpected(path + ": cannot read: " + std::strerror(reader->error()));
    if (line.empty()) continue;
    if (line[0] == '#') {
      const auto colon = line.find(':');
      if (colon == std::string_view::npos) continue;
      const std::string_view key = Trim(line.substr(1, colon - 1));
      const std::string value(Trim(line.substr(colon + 1)));
      if (key == "Max Latencies") max_us = std::atoll(value.c_str());
      if (key == "Histogram Overflows") h.overflow = std::strtoull(value.c_str(), nullptr, 10);
      if (key.starts_with("palpad ")) {
        h.palpad.emplace_back(std::string(key.substr(7)), value);
        if (key == "palpad max_ns") max_ns = value;
      }
      continue;
    }
    const std::string text(line);
    unsigned long long bin = 0, count = 0;
    if (std::sscanf(text.c_str(), "%llu %llu", &bin, &count) != 2 || bin >= kMaxBin)
      return std::unexpected(where + ": not a histogram line: '" + io::Escape(line) + "'");
    const auto i = static_cast<std::size_t>(bin);  // < kMaxBin: fits a 32-bit size_t
    if (h.bins.size() <= i) h.bins.resize(i + 1, 0);
    h.bins[i] += count;
  }
  if (max_us < 0) return std::unexpected(path + ": no '# Max Latencies' line (not a cyclictest histogram)");
  h.max_ns = !max_ns.empty() ? std::atoll(max_ns.c_str()) : max_us * 1000;
  h.count = h.overflow;
  for (const std::uint64_t c : h.bins) h.count += c;
  return h;
}

std::int64_t PercentileOfSamples(std::span<const std::int64_t> ns, double q) {
  if (ns.empty()) return 0;
  std::vector<std::int64_t> copy(ns.begin(), ns.end());
  const double rank = std::ceil(std::clamp(q, 0.0, 1.0) * static_cast<double>(copy.size()));
  const std::size_t index = std::min(rank < 1 ? 0 : static_cast<std::size_t>(rank) - 1, copy.size() - 1);
  std::nth_element(copy.begin(), copy.begin() + static_cast<std::ptrdiff_t>(index), copy.end());
  return copy[index];
}

}  // namespace palpa::record
