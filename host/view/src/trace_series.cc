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
#include "palpa/record/run_record.h"

namespace palpa::view {

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
      if (line != record::kCsvHeader)
        return std::unexpected(Error{fmt::format("{}:{}: expected palpad's CSV header '{}', got '{}'", file, n,
                                                 record::kCsvHeader, io::Escape(line))});
      header = true;
      continue;
    }
    auto row = record::ParseCsvRow(line);
    if (!row) return std::unexpected(Error{fmt::format("{}:{}: {}", file, n, row.error())});
    const record::LogRow& r = *row;
    if (!s.t_s.empty() && r.t_s < s.t_s.back())
      return std::unexpected(
          Error{fmt::format("{}:{}: time {} s is before the previous row's {} s", file, n, r.t_s, s.t_s.back())});
    s.t_s.push_back(r.t_s);
    s.hip_m.push_back(r.hip_m);
    s.proxy_m.push_back(r.proxy_m);
    s.force_n.push_back(r.force_n);
    s.contact.push_back(r.contact ? 1 : 0);
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
