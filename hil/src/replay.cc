#include "palpa/hil/replay.h"

#include <cmath>

#include <fmt/core.h>

#include "palpa/record/run_record.h"

namespace palpa::hil {

std::uint16_t RowHash(std::string_view line) {
  std::uint32_t h = 2166136261u;
  for (const char c : line) h = (h ^ static_cast<std::uint8_t>(c)) * 16777619u;
  return static_cast<std::uint16_t>(h ^ (h >> 16));
}

std::expected<std::vector<Tick>, std::string> ParseOutput(const std::string& csv, const std::string& name) {
  std::vector<Tick> ticks;
  std::size_t pos = csv.find('\n');
  if (pos == std::string::npos) return ticks;
  if (std::string_view(csv.data(), pos) != record::kCsvHeader)
    return std::unexpected(fmt::format("{}:1: expected palpad's CSV header '{}'", name, record::kCsvHeader));
  ++pos;
  std::size_t line_no = 1;
  while (pos < csv.size()) {
    std::size_t end = csv.find('\n', pos);
    if (end == std::string::npos) end = csv.size();
    const std::string_view line(csv.data() + pos, end - pos);
    pos = end + 1;
    ++line_no;
    if (line.empty()) continue;
    auto row = record::ParseCsvRow(line);
    if (!row) return std::unexpected(fmt::format("{}:{}: {}", name, line_no, row.error()));
    Tick t;
    t.t_s = row->t_s;
    for (std::size_t k = 0; k < 3; ++k) {
      t.hip[k] = row->hip_m[k];
      t.proxy[k] = row->proxy_m[k];
      t.force[k] = row->force_n[k];
      t.force_q24[k] = static_cast<std::int32_t>(std::llround(row->force_n[k] * kForceScale));
    }
    t.contact = row->contact;
    t.row_hash = RowHash(line);
    ticks.push_back(t);
  }
  return ticks;
}

}  // namespace palpa::hil
