#include "palpa/record/run_record.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <string>

#include "palpa/io/escape.h"

namespace palpa::record {

bool WriteCsvHeader(std::FILE* out) {
  return std::fprintf(out, "%.*s\n", static_cast<int>(kCsvHeader.size()), kCsvHeader.data()) >= 0;
}

bool WriteCsvRow(std::FILE* out, const LogRow& r) {
  return std::fprintf(out, "%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.12g,%.9g,%.9g,%.9g,%d\n", r.t_s, r.hip_m[0],
                      r.hip_m[1], r.hip_m[2], r.proxy_m[0], r.proxy_m[1], r.proxy_m[2], r.force_n[0], r.force_n[1],
                      r.force_n[2], r.contact ? 1 : 0) >= 0;
}

std::expected<LogRow, std::string> ParseCsvRow(std::string_view line) {
  std::array<double, kCsvColumns> v{};
  const char* p = line.data();
  const char* end = line.data() + line.size();
  for (std::size_t c = 0; c < v.size(); ++c) {
    const char* stop = std::find(p, end, ',');
    if ((c + 1 < v.size()) != (stop != end)) return std::unexpected(std::string("expected 11 comma-separated fields"));
    const auto [ptr, err] = std::from_chars(p, stop, v[c]);
    if (err != std::errc{} || ptr != stop || !std::isfinite(v[c]))
      return std::unexpected("field " + std::to_string(c + 1) + " '" +
                             io::Escape(std::string_view(p, static_cast<std::size_t>(stop - p))) +
                             "' is not a finite number");
    p = stop == end ? end : stop + 1;
  }
  if (v[10] != 0 && v[10] != 1) {
    char got[48];
    std::snprintf(got, sizeof got, "%g", v[10]);
    return std::unexpected("contact must be 0 or 1, got " + std::string(got));
  }
  LogRow r;
  r.t_s = v[0];
  for (std::size_t k = 0; k < 3; ++k) {
    r.hip_m[k] = v[1 + k];
    r.proxy_m[k] = v[4 + k];
    r.force_n[k] = v[7 + k];
  }
  r.contact = v[10] != 0;
  return r;
}

bool WriteTimingHeader(std::FILE* out) {
  return std::fprintf(out, "%.*s\n", static_cast<int>(kTimingCsvHeader.size()), kTimingCsvHeader.data()) >= 0;
}

bool WriteTimingRow(std::FILE* out, const TimingRow& r) {
  return std::fprintf(out, "%llu,%.9f,%lld,%lld,%lld,%u\n", static_cast<unsigned long long>(r.tick), r.t_s,
                      static_cast<long long>(r.wake_ns), static_cast<long long>(r.compute_ns),
                      static_cast<long long>(r.total_ns), r.flags) >= 0;
}

std::expected<TimingRow, std::string> ParseTimingRow(std::string_view line) {
  TimingRow r;
  const char* p = line.data();
  const char* end = line.data() + line.size();
  for (std::size_t c = 0; c < kTimingCsvColumns; ++c) {
    const char* stop = std::find(p, end, ',');
    if ((c + 1 < kTimingCsvColumns) != (stop != end))
      return std::unexpected(std::string("expected 6 comma-separated fields"));
    std::from_chars_result got{};
    switch (c) {
      case 0:
        got = std::from_chars(p, stop, r.tick);
        break;
      case 1:
        got = std::from_chars(p, stop, r.t_s);
        break;
      case 2:
        got = std::from_chars(p, stop, r.wake_ns);
        break;
      case 3:
        got = std::from_chars(p, stop, r.compute_ns);
        break;
      case 4:
        got = std::from_chars(p, stop, r.total_ns);
        break;
      default:
        got = std::from_chars(p, stop, r.flags);
        break;
    }
    if (got.ec != std::errc{} || got.ptr != stop || (c == 1 && !std::isfinite(r.t_s)))
      return std::unexpected("field " + std::to_string(c + 1) + " '" +
                             io::Escape(std::string_view(p, static_cast<std::size_t>(stop - p))) + "' is not " +
                             (c == 1 ? "a finite number" : "an integer"));
    p = stop == end ? end : stop + 1;
  }
  return r;
}

}  // namespace palpa::record
