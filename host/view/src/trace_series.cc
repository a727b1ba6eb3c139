// palpad's output CSV for the replay view.
#include "palpa/view/trace_series.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <fmt/core.h>
#include <nlohmann/json.hpp>

#include "palpa/io/escape.h"
#include "palpa/io/file_safety.h"

namespace palpa::view {
namespace {

constexpr const char* kHeader = "t_s,hip_x_m,hip_y_m,hip_z_m,proxy_x_m,proxy_y_m,proxy_z_m,fx_n,fy_n,fz_n,contact";

}  // namespace

std::expected<TraceSeries, Error> ReadTrace(const std::string& path) {
  std::string file = path;
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) file = (std::filesystem::path(path) / "out.csv").string();
  // Bounded: a regular file only, read line by line (a palpad row is ~150 bytes).
  auto in = io::LineReader::Open(file, 4096, "trace CSV");
  if (!in) return std::unexpected(Error{std::move(in.error().message)});
  TraceSeries s;
  s.source = file;
  file = io::Escape(file, 256);  // for messages
  std::string line;
  std::uint64_t n = 0;
  bool header = false;
  while (true) {
    std::string_view text;
    const io::LineReader::Status status = in->Next(text);
    n = in->line_number();
    if (status == io::LineReader::Status::kEnd) break;
    if (status == io::LineReader::Status::kTooLong)
      return std::unexpected(Error{fmt::format("{}:{}: the line is longer than 4096 bytes", file, n)});
    if (status == io::LineReader::Status::kError)
      return std::unexpected(Error{fmt::format("{}: read error: {}", file, std::strerror(in->error()))});
    line.assign(text);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    if (!header) {
      if (line != kHeader)
        return std::unexpected(Error{
            fmt::format("{}:{}: expected palpad's CSV header '{}', got '{}'", file, n, kHeader, io::Escape(line))});
      header = true;
      continue;
    }
    std::array<double, 11> v{};
    const char* p = line.data();
    const char* end = line.data() + line.size();
    for (std::size_t c = 0; c < v.size(); ++c) {
      const char* stop = std::find(p, end, ',');
      if ((c + 1 < v.size()) != (stop != end))
        return std::unexpected(Error{fmt::format("{}:{}: expected 11 comma-separated fields", file, n)});
      const auto [ptr, err] = std::from_chars(p, stop, v[c]);
      if (err != std::errc{} || ptr != stop || !std::isfinite(v[c]))
        return std::unexpected(Error{fmt::format("{}:{}: field {} '{}' is not a finite number", file, n, c + 1,
                                                 io::Escape(std::string_view(p, static_cast<std::size_t>(stop - p))))});
      p = stop == end ? end : stop + 1;
    }
    if (v[10] != 0 && v[10] != 1)
      return std::unexpected(Error{fmt::format("{}:{}: contact must be 0 or 1, got {}", file, n, v[10])});
    if (!s.t_s.empty() && v[0] < s.t_s.back())
      return std::unexpected(
          Error{fmt::format("{}:{}: time {} s is before the previous row's {} s", file, n, v[0], s.t_s.back())});
    s.t_s.push_back(v[0]);
    s.hip_m.push_back({v[1], v[2], v[3]});
    s.proxy_m.push_back({v[4], v[5], v[6]});
    s.force_n.push_back({v[7], v[8], v[9]});
    s.contact.push_back(static_cast<std::uint8_t>(v[10]));
  }
  if (!header) return std::unexpected(Error{fmt::format("{}: empty: no CSV header", file)});
  if (s.t_s.empty()) return std::unexpected(Error{fmt::format("{}: no rows after the header", file)});
  return s;
}

std::string TraceToJson(const TraceSeries& trace) {
  nlohmann::json j;
  j["source"] = trace.source;
  j["rows"] = trace.t_s.size();
  j["t_s"] = trace.t_s;
  j["hip_m"] = trace.hip_m;
  j["proxy_m"] = trace.proxy_m;
  j["force_n"] = trace.force_n;
  j["contact"] = trace.contact;
  return j.dump();
}

}  // namespace palpa::view
