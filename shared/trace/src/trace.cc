#include "palpa/trace/trace.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

namespace palpa::trace {
namespace {

std::unexpected<TraceError> Fail(const std::string& name, std::size_t line, const std::string& what) {
  return std::unexpected(
      TraceError{line, line > 0 ? name + ":" + std::to_string(line) + ": " + what : name + ": " + what});
}

}  // namespace

std::expected<std::vector<TraceSample>, TraceError> ParseTrace(const std::string& text, const std::string& name) {
  std::vector<TraceSample> out;
  std::size_t line_no = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    std::string_view line(text.data() + pos, end - pos);
    pos = end + 1;
    ++line_no;
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ' || line.back() == '\t')) line.remove_suffix(1);
    while (!line.empty() && (line.front() == ' ' || line.front() == '\t')) line.remove_prefix(1);
    if (line.empty() || line.front() == '#') continue;
    if (line.starts_with("t_s")) {
      if (line != "t_s,x_m,y_m,z_m") return Fail(name, line_no, "unknown column line (expected t_s,x_m,y_m,z_m)");
      continue;
    }
    double v[4];
    int count = 0;
    const char* p = line.data();
    const char* stop = line.data() + line.size();
    while (p < stop) {
      while (p < stop && (*p == ' ' || *p == '\t')) ++p;
      if (count == 4) return Fail(name, line_no, "more than 4 values (expected t_s,x_m,y_m,z_m)");
      double x = 0;
      const auto [next, ec] = std::from_chars(p, stop, x);
      if (ec != std::errc()) return Fail(name, line_no, "value " + std::to_string(count + 1) + " is not a number");
      v[count++] = x;
      p = next;
      while (p < stop && (*p == ' ' || *p == '\t')) ++p;
      if (p < stop) {
        if (*p != ',') return Fail(name, line_no, "expected ',' after value " + std::to_string(count));
        ++p;
      }
    }
    if (count != 4) return Fail(name, line_no, "expected 4 values t_s,x_m,y_m,z_m, found " + std::to_string(count));
    for (int i = 0; i < 4; ++i)
      if (!std::isfinite(v[i])) return Fail(name, line_no, "value " + std::to_string(i + 1) + " is not finite");
    if (!out.empty() && !(v[0] > out.back().t_s))
      return Fail(name, line_no, "time " + std::to_string(v[0]) + " s does not increase");
    out.push_back({v[0], {v[1], v[2], v[3]}});
  }
  if (out.size() < 2) return Fail(name, 0, "a trace needs at least 2 samples, found " + std::to_string(out.size()));
  return out;
}

std::expected<std::vector<TraceSample>, TraceError> ReadTrace(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Fail(path, 0, "cannot open trace file");
  std::ostringstream buf;
  buf << in.rdbuf();
  return ParseTrace(buf.str(), path);
}

std::string FormatTrace(const std::vector<TraceSample>& samples, const std::string& comment) {
  std::string out = "# palpa trace v1: HIP in device-frame metres, time in seconds\n";
  if (!comment.empty()) out += "# " + comment + "\n";
  out += "t_s,x_m,y_m,z_m\n";
  char line[128];
  for (const auto& s : samples) {
    const int n =
        std::snprintf(line, sizeof line, "%.9g,%.10g,%.10g,%.10g\n", s.t_s, s.hip_m[0], s.hip_m[1], s.hip_m[2]);
    if (n > 0) out.append(line, static_cast<std::size_t>(n));
  }
  return out;
}

std::array<double, 3> HipAt(const std::vector<TraceSample>& s, double t, std::size_t& hint) {
  if (t <= s.front().t_s) return s.front().hip_m;
  if (t >= s.back().t_s) return s.back().hip_m;
  if (hint >= s.size() - 1 || s[hint].t_s > t) hint = 0;
  while (hint + 1 < s.size() - 1 && s[hint + 1].t_s <= t) ++hint;  // bounded by the trace length
  const TraceSample& a = s[hint];
  const TraceSample& b = s[hint + 1];
  const double u = (t - a.t_s) / (b.t_s - a.t_s);
  return {a.hip_m[0] + (b.hip_m[0] - a.hip_m[0]) * u, a.hip_m[1] + (b.hip_m[1] - a.hip_m[1]) * u,
          a.hip_m[2] + (b.hip_m[2] - a.hip_m[2]) * u};
}

}  // namespace palpa::trace
