#include "palpa/hil/golden.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <sstream>

#include <fmt/core.h>
#include <fmt/format.h>
#include <nettle/sha2.h>
#include <toml++/toml.h>
#include <zlib.h>
#include <nlohmann/json.hpp>

#include "text.h"

namespace palpa::hil {

namespace fs = std::filesystem;

std::string Sha256Hex(std::string_view bytes) {
  sha256_ctx ctx;
  sha256_init(&ctx);
  sha256_update(&ctx, bytes.size(), reinterpret_cast<const std::uint8_t*>(bytes.data()));
  std::uint8_t digest[SHA256_DIGEST_SIZE];
  sha256_digest(&ctx, SHA256_DIGEST_SIZE, digest);
  std::string hex;
  for (const std::uint8_t b : digest) hex += fmt::format("{:02x}", b);
  return hex;
}

std::string Sha256HexOfFile(const fs::path& p) { return Sha256Hex(detail::Slurp(p)); }

std::string RawTicks(const std::vector<Tick>& ticks) {
  std::string raw;
  std::array<std::int64_t, 3> prev{};
  auto varint = [&](std::uint64_t u) {
    while (u >= 0x80) {
      raw += static_cast<char>((u & 0x7F) | 0x80);
      u >>= 7;
    }
    raw += static_cast<char>(u);
  };
  for (const Tick& t : ticks) {
    for (std::size_t k = 0; k < 3; ++k) {
      const std::int64_t d = t.force_q24[k] - prev[k];
      prev[k] = t.force_q24[k];
      varint((static_cast<std::uint64_t>(d) << 1) ^ static_cast<std::uint64_t>(d >> 63));
    }
    raw += static_cast<char>(t.contact ? 1 : 0);
    raw += static_cast<char>(t.flags);
    raw += static_cast<char>(t.row_hash & 0xFF);
    raw += static_cast<char>(t.row_hash >> 8);
  }
  return raw;
}

std::string EncodeTicks(const std::vector<Tick>& ticks) {
  std::string raw = RawTicks(ticks);
  z_stream z{};
  deflateInit2(&z, 9, Z_DEFLATED, 15 + 16, 9, Z_DEFAULT_STRATEGY);  // gzip wrapper, mtime 0
  std::string out(deflateBound(&z, static_cast<uLong>(raw.size())) + 32, '\0');
  z.next_in = reinterpret_cast<Bytef*>(raw.data());
  z.avail_in = static_cast<uInt>(raw.size());
  z.next_out = reinterpret_cast<Bytef*>(out.data());
  z.avail_out = static_cast<uInt>(out.size());
  deflate(&z, Z_FINISH);
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

std::expected<std::vector<Tick>, std::string> DecodeTicks(std::string_view gz, std::size_t count) {
  std::string raw;
  z_stream z{};
  inflateInit2(&z, 15 + 16);
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(gz.data()));
  z.avail_in = static_cast<uInt>(gz.size());
  char buf[65536];
  int rc = Z_OK;
  while (rc == Z_OK) {
    z.next_out = reinterpret_cast<Bytef*>(buf);
    z.avail_out = sizeof buf;
    rc = inflate(&z, Z_NO_FLUSH);
    raw.append(buf, sizeof buf - z.avail_out);
  }
  // zlib stops where it finds the damage (a bad header, code or check value) or where the input
  // runs out: that byte, with its reason, is what a person looking at the file needs.
  const std::string reason = z.msg != nullptr ? z.msg : "truncated";
  const uLong stopped_at = z.total_in;
  inflateEnd(&z);
  if (rc != Z_STREAM_END)
    return std::unexpected(
        fmt::format("corrupt golden tick stream (gzip) at byte {} of {}: {}", stopped_at, gz.size(), reason));
  std::vector<Tick> ticks;
  std::array<std::int64_t, 3> prev{};
  std::size_t at = 0;
  auto varint = [&](std::uint64_t& u) {
    u = 0;
    for (int shift = 0; at < raw.size() && shift < 64; shift += 7) {
      const auto b = static_cast<std::uint8_t>(raw[at++]);
      u |= static_cast<std::uint64_t>(b & 0x7F) << shift;
      if ((b & 0x80) == 0) return true;
    }
    return false;
  };
  const auto early = [&](std::size_t tick) {
    return std::unexpected(
        fmt::format("golden tick stream ends early: tick {} of {} needs byte {} of {} (uncompressed)", tick, count, at,
                    raw.size()));
  };
  for (std::size_t i = 0; i < count; ++i) {
    Tick t;
    for (std::size_t k = 0; k < 3; ++k) {
      std::uint64_t u = 0;
      if (!varint(u)) return early(i);
      const auto d = static_cast<std::int64_t>(u >> 1) ^ -static_cast<std::int64_t>(u & 1);
      prev[k] += d;
      t.force_q24[k] = static_cast<std::int32_t>(prev[k]);
      t.force[k] = static_cast<double>(prev[k]) / kForceScale;
    }
    if (at + 4 > raw.size()) return early(i);
    t.contact = raw[at] != 0;
    t.flags = static_cast<std::uint8_t>(raw[at + 1]);
    t.row_hash = static_cast<std::uint16_t>(static_cast<std::uint8_t>(raw[at + 2]) |
                                            (static_cast<std::uint8_t>(raw[at + 3]) << 8));
    at += 4;
    ticks.push_back(t);
  }
  return ticks;
}

std::map<std::string, std::string> Counters(const std::string& summary_json) {
  std::map<std::string, std::string> out;
  const auto summary = nlohmann::ordered_json::parse(summary_json, nullptr, /*allow_exceptions=*/false);
  if (!summary.is_object()) return out;
  for (const char* key : {"ticks", "contact_ticks", "force_clamps", "device_errors", "dropped_rows", "estop_events",
                          "estop_ticks", "gpio_errors", "end", "fault"}) {
    const auto it = summary.find(key);
    if (it == summary.end()) continue;
    out[key] = it->is_string() ? it->get<std::string>() : it->dump();
  }
  return out;
}

fs::path GoldenTomlPath(const fs::path& dir, const std::string& name) { return dir / (name + ".toml"); }
fs::path GoldenTicksPath(const fs::path& dir, const std::string& name) { return dir / (name + ".ticks.gz"); }

std::string GoldenToml(const Case& c, const FieldSpec& field, const Settings& settings, const Replay& r,
                       const std::string& trace_sha256) {
  toml::table counters;
  for (const auto& [k, v] : Counters(r.summary_json)) counters.insert(k, v);
  toml::table t{{"format", "palpa-hil-golden 1"},
                {"case", c.name},
                {"trace", c.trace},
                {"trace_sha256", trace_sha256},
                {"field_build", field.blob.empty() ? field.build : "blob " + field.blob},
                {"device", c.device},
                {"palpad_args", detail::Join(c.palpad)},
                {"k_n_per_m", settings.k_n_per_m},
                {"max_force_n", settings.max_force_n},
                {"rate_hz", settings.rate_hz},
                {"exit_code", r.exit_code},
                {"ticks", static_cast<std::int64_t>(r.ticks.size())},
                {"csv_sha256", Sha256Hex(r.csv)},
                {"ticks_sha256", Sha256Hex(RawTicks(r.ticks))},
                {"counters", counters},
                {"device_report", r.device_report}};
  std::ostringstream out;
  out << "# HIL golden for case " << c.name << " (palpa hil bless " << c.name << "); do not edit by hand.\n"
      << "# Per-tick forces, contact and row hashes: " << c.name << ".ticks.gz (docs/hil.md).\n"
      << t << "\n";
  return out.str();
}

std::expected<Golden, std::string> ReadGolden(const fs::path& dir, const std::string& name) {
  const fs::path p = GoldenTomlPath(dir, name);
  if (!fs::exists(p)) return std::unexpected("no golden " + p.string() + " (bless it: palpa hil bless " + name + ")");
  toml::table t;
  try {
    t = toml::parse_file(p.string());
  } catch (const toml::parse_error& e) {
    return std::unexpected(fmt::format("{}:{}: {}", p.string(), e.source().begin.line, e.description()));
  }
  Golden g;
  g.csv_sha256 = t["csv_sha256"].value_or(std::string());
  g.ticks_sha256 = t["ticks_sha256"].value_or(std::string());
  g.ticks = static_cast<std::size_t>(t["ticks"].value_or(std::int64_t{0}));
  g.exit_code = static_cast<int>(t["exit_code"].value_or(std::int64_t{0}));
  g.device_report = t["device_report"].value_or(std::string());
  if (auto* cs = t["counters"].as_table())
    for (auto&& [k, v] : *cs) g.counters[std::string(k.str())] = v.value_or(std::string());
  return g;
}

bool Reproduces(const Golden& g, const Replay& r) {
  return g.csv_sha256 == Sha256Hex(r.csv) && g.ticks_sha256 == Sha256Hex(RawTicks(r.ticks)) &&
         g.exit_code == r.exit_code && g.device_report == r.device_report && g.counters == Counters(r.summary_json);
}

std::string Differences(const fs::path& dir, const std::string& name, const Golden& g, const Replay& r) {
  using detail::Replace;
  std::string out;
  if (g.exit_code != r.exit_code) out += fmt::format("    exit code {} (golden {})\n", r.exit_code, g.exit_code);
  if (g.ticks != r.ticks.size()) out += fmt::format("    ticks {} (golden {})\n", r.ticks.size(), g.ticks);
  const auto counters = Counters(r.summary_json);
  for (const auto& [k, v] : g.counters) {
    auto it = counters.find(k);
    const std::string now = it == counters.end() ? "(missing)" : it->second;
    if (now != v) out += fmt::format("    {} {} (golden {})\n", k, now, v);
  }
  if (g.device_report != r.device_report)
    out += fmt::format("    device report:\n      now:    {}\n      golden: {}\n", Replace(r.device_report, "\n", " "),
                       Replace(g.device_report, "\n", " "));
  const fs::path ticks_path = GoldenTicksPath(dir, name);
  auto gt = DecodeTicks(detail::Slurp(ticks_path), g.ticks);
  if (!gt) return out + "    " + ticks_path.string() + ": " + gt.error() + "\n";
  std::size_t changed = 0, force_changed = 0, first = SIZE_MAX;
  double max_df = 0;
  std::size_t max_df_tick = 0;
  const std::size_t n = std::min(gt->size(), r.ticks.size());
  for (std::size_t i = 0; i < n; ++i) {
    const Tick& a = (*gt)[i];
    const Tick& b = r.ticks[i];
    const bool f_diff = a.force_q24 != b.force_q24;
    if (f_diff || a.row_hash != b.row_hash || a.contact != b.contact || a.flags != b.flags) {
      ++changed;
      first = std::min(first, i);
    }
    if (f_diff) {
      ++force_changed;
      const double df = std::hypot(a.force[0] - b.force[0], a.force[1] - b.force[1], a.force[2] - b.force[2]);
      if (df > max_df) {
        max_df = df;
        max_df_tick = i;
      }
    }
  }
  changed += std::max(gt->size(), r.ticks.size()) - n;
  out += fmt::format(
      "    ticks changed: {} of {} (forces on {}), first at tick {}; max force difference {:.6g} N at tick {}\n",
      changed, std::max(gt->size(), r.ticks.size()), force_changed,
      first == SIZE_MAX ? std::string("-") : std::to_string(first), max_df, max_df_tick);
  return out;
}

}  // namespace palpa::hil
