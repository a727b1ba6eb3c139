// palpa hil run | bless | report: hardware-in-the-loop replay (docs/hil.md). Each case in
// hil/cases.toml replays a trace from hil/traces/ through the palpad binary (the same fixed-point
// core and device layer as on the board) on a field built at run time from the bundled data.
//  - fast (lockstep): the per-tick output must match the committed golden bit for bit;
//  - realtime: paced on the wall clock; checks invariants and reports latency, never goldens.
// Both modes check the invariants (proxy outside, clamp, force slope, passivity) and, for the
// sphere, the paper's Fig. 9 validation against the analytic force. Non-RT host code.
#include <fcntl.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include <fmt/core.h>
#include <fmt/format.h>
#include <nettle/sha2.h>
#include <toml++/toml.h>
#include <zlib.h>
#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "field_sampler.h"
#include "palpa/blob/blob.h"
#include "palpa/io/atomic_file.h"
#include "palpa/record/run_record.h"
#include "palpa/trace/trace.h"

extern char** environ;

namespace palpa::cli {
namespace {

namespace fs = std::filesystem;

constexpr int kExitFailed = 1;              // a replay did not match or broke an invariant
constexpr double kForceScale = 16777216.0;  // goldens store forces in units of 2^-24 N

// ---------------------------------------------------------------- small helpers

std::string Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

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

// result.json and index.json keep their keys in the order written.
using Json = nlohmann::ordered_json;

std::vector<std::string> SplitWords(std::string_view s) {
  std::vector<std::string> out;
  std::istringstream in{std::string(s)};
  for (std::string w; in >> w;) out.push_back(w);
  return out;
}

std::string Replace(std::string s, std::string_view what, const std::string& with) {
  for (std::size_t p = s.find(what); p != std::string::npos; p = s.find(what, p + with.size()))
    s.replace(p, what.size(), with);
  return s;
}

std::string Join(const std::vector<std::string>& v, std::string_view sep = " ") {
  std::string out;
  for (const auto& s : v) out += (out.empty() ? "" : std::string(sep)) + s;
  return out;
}

bool WriteText(const fs::path& p, std::string_view text, std::string& error) {
  auto w = io::WriteFileAtomically(p.string(), std::as_bytes(std::span(text.data(), text.size())));
  if (!w) error = w.error();
  return w.has_value();
}

// Runs argv with stdout/stderr to files; returns the exit status (128+signal, −1 if not started).
int Spawn(const std::vector<std::string>& argv, const fs::path& out, const fs::path& err, const fs::path& cwd) {
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&fa, 2, err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addchdir_np(&fa, cwd.c_str());
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, args[0], &fa, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0) return -1;
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) return -1;
  }
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return -1;
}

fs::path SelfExe() {
  std::error_code ec;
  auto p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : p;
}

// ---------------------------------------------------------------- cases

struct FieldSpec {
  std::vector<std::string> prepare;  // palpa commands run first ({work} substituted)
  std::string build;                 // palpa build ... (without -o)
  std::string blob;                  // or a committed blob, relative to the suite's root
};

struct Limits {
  double phi_tolerance_voxels = 0.26;  // proxy never inside: φ(proxy) ≥ −this (δ = 0.25 voxel + rounding)
  double slope_factor = 2.0;           // |Δf| ≤ factor·k·(|ΔX_h| + |ΔX_p|) + slope_floor_n per tick
  double slope_floor_n = 0.01;
  double energy_tolerance_j = 1e-6;  // passivity: E_n ≥ −B_n − this
};

struct Case {
  std::string name, trace, field, device, why;
  std::vector<std::string> palpad;  // extra palpad arguments
  int expect_exit = 0;
  std::optional<std::array<double, 3>> sphere_centre_m;
  double sphere_radius_m = 0;
  std::optional<double> validate_rms_pct, validate_angle_deg;
  bool realtime = true;  // also replayed by --realtime
  // A field swap mid-replay (palpad --swap-at): tick swap_at runs on swap_field.
  std::string swap_field;
  std::int64_t swap_at = -1;
  // Known failures (substrings of failure sentences), each with its reason in cases.toml: reported
  // as "known", not counted; one that no longer occurs is reported so that it gets removed.
  std::vector<std::string> xfail;
  // A palpad output CSV (relative to the case list) measured instead of a replay: checks the
  // invariants on a run made elsewhere (and lets tests feed violating runs); never a golden.
  std::string output;
};

struct Suite {
  fs::path root, hil_dir, cases_path;
  double rate_hz = 1000, k_n_per_m = 800, max_force_n = 8;
  Limits limits;
  std::map<std::string, FieldSpec> fields;
  std::vector<Case> cases;
};

std::expected<Suite, std::string> LoadSuite(const fs::path& cases_path) {
  Suite s;
  s.cases_path = fs::absolute(cases_path);
  s.hil_dir = s.cases_path.parent_path();
  s.root = s.hil_dir.parent_path();
  toml::table t;
  try {
    t = toml::parse_file(s.cases_path.string());
  } catch (const toml::parse_error& e) {
    return std::unexpected(fmt::format("{}:{}:{}: {}", s.cases_path.string(), e.source().begin.line,
                                       e.source().begin.column, e.description()));
  }
  auto where = [&](const toml::node& n) { return fmt::format("{}:{}", s.cases_path.string(), n.source().begin.line); };
  if (auto* d = t["defaults"].as_table()) {
    s.rate_hz = (*d)["rate_hz"].value_or(s.rate_hz);
    s.k_n_per_m = (*d)["k_n_per_m"].value_or(s.k_n_per_m);
    s.max_force_n = (*d)["max_force_n"].value_or(s.max_force_n);
    s.limits.phi_tolerance_voxels = (*d)["phi_tolerance_voxels"].value_or(s.limits.phi_tolerance_voxels);
    s.limits.slope_factor = (*d)["slope_factor"].value_or(s.limits.slope_factor);
    s.limits.slope_floor_n = (*d)["slope_floor_n"].value_or(s.limits.slope_floor_n);
    s.limits.energy_tolerance_j = (*d)["energy_tolerance_j"].value_or(s.limits.energy_tolerance_j);
  }
  auto* fields = t["fields"].as_table();
  if (fields == nullptr) return std::unexpected(s.cases_path.string() + ": no [fields] table");
  for (auto&& [key, node] : *fields) {
    auto* ft = node.as_table();
    if (ft == nullptr) return std::unexpected(where(node) + ": fields." + std::string(key.str()) + " is not a table");
    FieldSpec f;
    auto build = (*ft)["build"].value<std::string>();
    auto blob = (*ft)["blob"].value<std::string>();
    if (blob && !build) {
      f.blob = *blob;  // a field palpa build can no longer make (e.g. one cut by its grid)
    } else if (!build || !build->starts_with("build ") || blob) {
      return std::unexpected(where(node) + ": fields." + std::string(key.str()) +
                             " needs either build = 'build POINTS ...' or blob = 'PATH'");
    } else {
      f.build = *build;
    }
    if (auto* prep = (*ft)["prepare"].as_array())
      for (auto&& p : *prep)
        if (auto v = p.value<std::string>()) f.prepare.push_back(*v);
    s.fields[std::string(key.str())] = f;
  }
  auto* cases = t["case"].as_array();
  if (cases == nullptr) return std::unexpected(s.cases_path.string() + ": no [[case]] entries");
  for (auto&& node : *cases) {
    auto* ct = node.as_table();
    if (ct == nullptr) return std::unexpected(where(node) + ": [[case]] is not a table");
    Case c;
    c.name = (*ct)["name"].value_or(std::string());
    c.trace = (*ct)["trace"].value_or(std::string());
    c.field = (*ct)["field"].value_or(std::string());
    c.device = (*ct)["device"].value_or(std::string("sim"));
    c.why = (*ct)["why"].value_or(std::string());
    c.expect_exit = (*ct)["expect_exit"].value_or(0);
    c.realtime = (*ct)["realtime"].value_or(true);
    c.swap_field = (*ct)["swap_field"].value_or(std::string());
    c.swap_at = (*ct)["swap_at"].value_or(std::int64_t{-1});
    c.output = (*ct)["output"].value_or(std::string());
    if (c.name.empty() || c.trace.empty() || c.field.empty())
      return std::unexpected(where(node) + ": a case needs name, trace and field");
    // Errors about a key name the key's own line.
    auto at = [&](const char* key) {
      const toml::node* n = ct->get(key);
      return where(n != nullptr ? *n : node);
    };
    if (!s.fields.contains(c.field)) return std::unexpected(at("field") + ": unknown field '" + c.field + "'");
    if (!c.swap_field.empty() && !s.fields.contains(c.swap_field))
      return std::unexpected(at("swap_field") + ": unknown field '" + c.swap_field + "'");
    if (c.swap_field.empty() != (c.swap_at < 0))
      return std::unexpected(where(node) + ": swap_field and swap_at (a tick ≥ 0) go together");
    if (c.device != "sim" && c.device != "virtual-falcon")
      return std::unexpected(at("device") + ": device must be sim or virtual-falcon");
    if (c.why.empty()) return std::unexpected(where(node) + ": case " + c.name + " must say why (its device choice)");
    if (auto* xf = (*ct)["xfail"].as_array())
      for (auto&& a : *xf)
        if (auto v = a.value<std::string>()) c.xfail.push_back(*v);
    if (auto* args = (*ct)["palpad"].as_array())
      for (auto&& a : *args)
        if (auto v = a.value<std::string>()) c.palpad.push_back(*v);
    if (auto* sph = (*ct)["sphere"].as_table()) {
      auto* centre = (*sph)["centre_m"].as_array();
      if (centre == nullptr || centre->size() != 3)
        return std::unexpected(where(node) + ": sphere.centre_m needs 3 numbers");
      c.sphere_centre_m =
          std::array<double, 3>{(*centre)[0].value_or(0.0), (*centre)[1].value_or(0.0), (*centre)[2].value_or(0.0)};
      c.sphere_radius_m = (*sph)["radius_m"].value_or(0.0);
      if (auto v = (*sph)["validate_rms_pct"].value<double>()) c.validate_rms_pct = *v;
      if (auto v = (*sph)["validate_angle_deg"].value<double>()) c.validate_angle_deg = *v;
    }
    for (const auto& other : s.cases)
      if (other.name == c.name) return std::unexpected(where(node) + ": duplicate case name " + c.name);
    s.cases.push_back(std::move(c));
  }
  return s;
}

std::optional<fs::path> FindCases() {
  for (fs::path dir : {fs::current_path(), SelfExe().parent_path()}) {
    for (; !dir.empty(); dir = dir.parent_path()) {
      if (fs::exists(dir / "hil" / "cases.toml")) return dir / "hil" / "cases.toml";
      if (dir == dir.root_path()) break;
    }
  }
  return std::nullopt;
}

// ---------------------------------------------------------------- one replay's output

struct Tick {
  double t_s = 0;
  std::array<double, 3> hip{}, proxy{}, force{};
  bool contact = false;
  std::array<std::int32_t, 3> force_q24{};  // force in 2^-24 N
  std::uint16_t row_hash = 0;               // FNV-1a of the row text, folded
  std::uint8_t flags = 0;                   // telemetry flags that are deterministic (record::kDeterministicFlags)
};

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

// Golden per-tick stream: per tick zigzag-varint deltas of the three forces (2^-24 N), a
// contact byte and the 16-bit row hash; gzip-compressed.
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

std::expected<std::vector<Tick>, std::string> DecodeTicks(const std::string& gz, std::size_t count) {
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
  inflateEnd(&z);
  if (rc != Z_STREAM_END) return std::unexpected("corrupt golden tick stream (gzip)");
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
  for (std::size_t i = 0; i < count; ++i) {
    Tick t;
    for (std::size_t k = 0; k < 3; ++k) {
      std::uint64_t u = 0;
      if (!varint(u)) return std::unexpected("golden tick stream ends early");
      const auto d = static_cast<std::int64_t>(u >> 1) ^ -static_cast<std::int64_t>(u & 1);
      prev[k] += d;
      t.force_q24[k] = static_cast<std::int32_t>(prev[k]);
      t.force[k] = static_cast<double>(prev[k]) / kForceScale;
    }
    if (at + 4 > raw.size()) return std::unexpected("golden tick stream ends early");
    t.contact = raw[at] != 0;
    t.flags = static_cast<std::uint8_t>(raw[at + 1]);
    t.row_hash = static_cast<std::uint16_t>(static_cast<std::uint8_t>(raw[at + 2]) |
                                            (static_cast<std::uint8_t>(raw[at + 3]) << 8));
    at += 4;
    ticks.push_back(t);
  }
  return ticks;
}

// ---------------------------------------------------------------- timing (palpad --record-timing)

struct TimingRow {
  std::int64_t wake_ns = -1, compute_ns = 0, total_ns = 0;
  std::uint32_t flags = 0;
};

std::vector<TimingRow> ReadTiming(const fs::path& p) {
  std::vector<TimingRow> rows;
  std::ifstream in(p);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    unsigned long long tick = 0;
    double t = 0;
    long long w = 0, c = 0, tot = 0;
    unsigned flags = 0;
    if (std::sscanf(line.c_str(), "%llu,%lf,%lld,%lld,%lld,%u", &tick, &t, &w, &c, &tot, &flags) == 6)
      rows.push_back({w, c, tot, flags});
  }
  return rows;
}

struct Percentiles {
  std::size_t count = 0;
  double p50 = 0, p99 = 0, p999 = 0, max = 0;  // µs
};

Percentiles Figures(std::vector<std::int64_t> ns) {
  Percentiles p;
  std::erase_if(ns, [](std::int64_t v) { return v < 0; });
  if (ns.empty()) return p;
  std::sort(ns.begin(), ns.end());
  auto rank = [&](double q) {  // nearest rank
    const auto r = static_cast<std::size_t>(std::ceil(q * static_cast<double>(ns.size())));
    return static_cast<double>(ns[std::min(ns.size(), std::max<std::size_t>(r, 1)) - 1]) / 1e3;
  };
  p.count = ns.size();
  p.p50 = rank(0.5);
  p.p99 = rank(0.99);
  p.p999 = rank(0.999);
  p.max = static_cast<double>(ns.back()) / 1e3;
  return p;
}

// ---------------------------------------------------------------- metrics

struct Metrics {
  std::size_t ticks = 0, contact_ticks = 0;
  double max_force_n = 0, max_slope_n = 0, slope_limit_n = 0, min_proxy_phi_voxels = 1e9;
  std::size_t releases = 0;  // contact ends with a force above the slope limit (god-object release)
  double max_release_n = 0;
  // Issue 19: worst |Δf| − limit over the ticks held to the slope limit (≤ 0 passes), the deepest
  // HIP (its distance from the proxy while inside, mm), holds (runs of ticks with a force and the
  // HIP outside: the proxy held on a blocked way) and the longest, ticks with a force while the way
  // is clear, drops to zero with the HIP inside, forces with the proxy off the surface.
  double worst_slope_excess_n = -1e9, deepest_hip_mm = 0;
  std::size_t holds = 0, longest_hold_ticks = 0, clear_way_force_ticks = 0, drops_inside = 0,
              off_surface_force_ticks = 0;
  double energy_j = 0, min_passivity_margin_j = 0;
  double max_hip_step_m = 0;
  // Sphere (analytic) validation, when the case has one.
  bool analytic = false;
  double peak_analytic_n = 0, rms_error_n = 0, rms_error_pct = 0, rms_angle_deg = 0, max_angle_deg = 0;
  std::size_t angle_ticks = 0;
  std::vector<std::string> failures;  // invariant and validation failures, one sentence each
};

// `swap_field`: the field from tick c.swap_at on (a swap case), else nullptr.
Metrics Measure(const std::vector<Tick>& ticks, const Case& c, const FieldSampler& first_field,
                const FieldSampler* swap_field, double k, double max_force, const Limits& lim) {
  Metrics m;
  m.ticks = ticks.size();
  for (std::size_t i = 1; i < ticks.size(); ++i) {
    const Eigen::Vector3d d(ticks[i].hip[0] - ticks[i - 1].hip[0], ticks[i].hip[1] - ticks[i - 1].hip[1],
                            ticks[i].hip[2] - ticks[i - 1].hip[2]);
    m.max_hip_step_m = std::max(m.max_hip_step_m, d.norm());
  }
  m.slope_limit_n = lim.slope_factor * k * m.max_hip_step_m + lim.slope_floor_n;
  double energy = 0, bound = 0;
  std::size_t worst_phi_tick = 0, worst_slope_tick = 0, clear_tick = 0, drop_tick = 0, off_tick = 0;
  std::size_t hold_run = 0, clear_run = 0;
  double worst_off_phi = 0;
  // The proxy is not run during an e-stop, and restarts at the HIP after it, following the HIP
  // with zero force until the HIP has been outside once (proxy::ProxyTick): "never inside"
  // holds from then on. Unseated ticks are not checked (a trace starts outside: seated at once).
  bool seated = false;
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    const Tick& t = ticks[i];
    const Eigen::Vector3d f(t.force[0], t.force[1], t.force[2]);
    const Eigen::Vector3d proxy(t.proxy[0], t.proxy[1], t.proxy[2]);
    m.contact_ticks += t.contact ? 1 : 0;
    m.max_force_n = std::max(m.max_force_n, f.norm());
    const bool swapped = swap_field != nullptr && c.swap_at >= 0 && i >= static_cast<std::size_t>(c.swap_at);
    const FieldSampler& field_at = swapped ? *swap_field : first_field;
    if ((t.flags & record::kFlagEstop) != 0) seated = false;
    // A swap whose HIP is beyond the new field's band restarts the proxy at the HIP (docs/upload.md).
    if ((t.flags & record::kFlagSwap) != 0 && t.proxy == t.hip) seated = false;
    if (!seated)
      seated = (t.flags & record::kFlagEstop) == 0 && field_at.Phi(Eigen::Vector3d(t.hip[0], t.hip[1], t.hip[2])) >= 0;
    const double phi_voxels = seated ? field_at.Phi(proxy) / field_at.voxel_m() : m.min_proxy_phi_voxels;
    if (phi_voxels < m.min_proxy_phi_voxels) {
      m.min_proxy_phi_voxels = phi_voxels;
      worst_phi_tick = i;
    }
    // Issue 19's invariants, in voxels of the field in force at this tick.
    const double vox = field_at.voxel_m();
    const Eigen::Vector3d hip(t.hip[0], t.hip[1], t.hip[2]);
    const double phi_h = field_at.Phi(hip) / vox;
    const double fn = f.norm();
    const bool exempt = (t.flags & (record::kFlagEstop | record::kFlagRamp)) != 0;
    if (fn > 0 && phi_h < 0) m.deepest_hip_mm = std::max(m.deepest_hip_mm, 1e3 * (hip - proxy).norm());
    // Held: a force with the HIP outside. Allowed only while the straight way from the proxy runs
    // into the object: deeper than where the proxy rests (or the surface) by more than δ/4 (δ =
    // the proxy's depth tolerance, here phi_tolerance); a clear way may keep the force for its
    // release tick, not two.
    const bool outside = phi_h >= 0.01;
    if (fn > 0 && outside && seated && !exempt) {
      if (++hold_run == 1) ++m.holds;
      m.longest_hold_ticks = std::max(m.longest_hold_ticks, hold_run);
      const double floor = std::min(phi_voxels, 0.0) - 0.25 * lim.phi_tolerance_voxels;
      bool clear = true;
      const Eigen::Vector3d d = hip - proxy;
      const int steps = 1 + static_cast<int>(16.0 * d.norm() / vox);  // every 1/16 voxel
      for (int s = 0; s <= steps && clear; ++s) clear = field_at.Phi(proxy + d * (double(s) / steps)) / vox >= floor;
      clear_run = clear ? clear_run + 1 : 0;
      if (clear_run >= 2) {
        if (m.clear_way_force_ticks++ == 0) clear_tick = i;
      }
    } else {
      hold_run = 0;
      clear_run = 0;
    }
    // The proxy at the surface whenever the force is felt: |φ(proxy)| ≤ ½ voxel (+ rounding).
    if (fn > 0.05 && seated && !exempt && std::abs(phi_voxels) > 0.51) {
      if (m.off_surface_force_ticks++ == 0) off_tick = i, worst_off_phi = phi_voxels;
    }
    if (i > 0) {
      const Tick& p = ticks[i - 1];
      const double slope =
          Eigen::Vector3d(t.force[0] - p.force[0], t.force[1] - p.force[1], t.force[2] - p.force[2]).norm();
      const double pn = Eigen::Vector3d(p.force[0], p.force[1], p.force[2]).norm();
      // No drop to zero while the HIP is inside.
      if (pn > 0 && fn == 0 && phi_h < -0.01 && !exempt && seated) {
        if (m.drops_inside++ == 0) drop_tick = i;
      }
      // A spring changes only as fast as its ends move: |Δf| ≤ factor·k·(|ΔX_h| + |ΔX_p|) + floor.
      // A force that ends with the HIP outside is a release (the god-object proxy leaves the surface
      // at a silhouette, or round a part the HIP went through, once the way is clear: Zilles &
      // Salisbury 1995): counted and reported, not held to the limit. Every rise, every change in
      // contact and every end with the HIP inside is.
      const double dh = Eigen::Vector3d(t.hip[0] - p.hip[0], t.hip[1] - p.hip[1], t.hip[2] - p.hip[2]).norm();
      const double dp =
          Eigen::Vector3d(t.proxy[0] - p.proxy[0], t.proxy[1] - p.proxy[1], t.proxy[2] - p.proxy[2]).norm();
      const double limit = lim.slope_factor * k * (dh + dp) + lim.slope_floor_n;
      if (fn == 0 && pn > 0 && phi_h >= -0.01 && slope > limit) {
        ++m.releases;
        m.max_release_n = std::max(m.max_release_n, slope);
      } else if (!exempt && slope - limit > m.worst_slope_excess_n) {
        m.worst_slope_excess_n = slope - limit;
        m.max_slope_n = slope;
        worst_slope_tick = i;
      }
      // Passivity observer (Hannaford & Ryu 2002), zero-order hold: E_n = −Σ f_m·(x_{m+1} − x_m);
      // a sampled spring may return at most B_n = k/2 Σ|Δx_h|² over the intervals that start or
      // end in contact (docs/realtime-core.md § Passivity observer; as proxy::PassivityObserver).
      double work = 0, dh2 = 0;
      for (std::size_t a = 0; a < 3; ++a) {
        work += p.force[a] * (t.hip[a] - p.hip[a]);
        dh2 += (t.hip[a] - p.hip[a]) * (t.hip[a] - p.hip[a]);
      }
      energy -= work;
      if (p.contact || t.contact) bound += 0.5 * k * dh2;
      m.min_passivity_margin_j = std::min(m.min_passivity_margin_j, energy + bound);
    }
  }
  m.energy_j = energy;
  if (m.max_force_n > max_force + 1e-4)
    m.failures.push_back(fmt::format("force {:.6f} N exceeds the clamp {} N", m.max_force_n, max_force));
  if (m.min_proxy_phi_voxels < -lim.phi_tolerance_voxels)
    m.failures.push_back(fmt::format("proxy inside the object at tick {}: φ = {:.4f} voxel < −{} voxel", worst_phi_tick,
                                     m.min_proxy_phi_voxels, lim.phi_tolerance_voxels));
  if (m.worst_slope_excess_n > 0)
    m.failures.push_back(fmt::format("force step {:.4f} N at tick {} exceeds the slope limit by {:.4f} N",
                                     m.max_slope_n, worst_slope_tick, m.worst_slope_excess_n));
  if (m.clear_way_force_ticks > 0)
    m.failures.push_back(
        fmt::format("force with the way clear (HIP outside, the straight way from the proxy never "
                    "below −{:.3f} voxel) on {} ticks beyond the release tick, first at tick {}",
                    0.5 * lim.phi_tolerance_voxels, m.clear_way_force_ticks, clear_tick));
  if (m.drops_inside > 0)
    m.failures.push_back(
        fmt::format("force dropped to zero with the HIP inside {} times, first at tick {}", m.drops_inside, drop_tick));
  if (m.off_surface_force_ticks > 0)
    m.failures.push_back(
        fmt::format("force above 0.05 N with the proxy off the surface (|φ| > ½ voxel) on {} ticks, "
                    "first at tick {} (φ = {:.3f} voxel)",
                    m.off_surface_force_ticks, off_tick, worst_off_phi));
  if (m.min_passivity_margin_j < -lim.energy_tolerance_j)
    m.failures.push_back(fmt::format("passivity observer: energy fell {:.3g} J below the sampled-spring bound",
                                     -m.min_passivity_margin_j));

  if (c.sphere_centre_m) {
    m.analytic = true;
    const Eigen::Vector3d centre((*c.sphere_centre_m)[0], (*c.sphere_centre_m)[1], (*c.sphere_centre_m)[2]);
    std::vector<double> fa(ticks.size());
    for (std::size_t i = 0; i < ticks.size(); ++i) {
      const Eigen::Vector3d h(ticks[i].hip[0], ticks[i].hip[1], ticks[i].hip[2]);
      fa[i] = std::min(k * std::max(0.0, c.sphere_radius_m - (h - centre).norm()), max_force);
      m.peak_analytic_n = std::max(m.peak_analytic_n, fa[i]);
    }
    double se = 0, sa = 0;
    for (std::size_t i = 0; i < ticks.size(); ++i) {
      const Eigen::Vector3d f(ticks[i].force[0], ticks[i].force[1], ticks[i].force[2]);
      se += (f.norm() - fa[i]) * (f.norm() - fa[i]);
      if (fa[i] >= 0.1 * m.peak_analytic_n && f.norm() > 0) {
        const Eigen::Vector3d h(ticks[i].hip[0], ticks[i].hip[1], ticks[i].hip[2]);
        const Eigen::Vector3d n = (h - centre).normalized();
        const double angle = std::acos(std::clamp(f.normalized().dot(n), -1.0, 1.0)) * 180.0 / M_PI;
        sa += angle * angle;
        m.max_angle_deg = std::max(m.max_angle_deg, angle);
        ++m.angle_ticks;
      }
    }
    m.rms_error_n = ticks.empty() ? 0 : std::sqrt(se / static_cast<double>(ticks.size()));
    m.rms_error_pct = m.peak_analytic_n > 0 ? 100 * m.rms_error_n / m.peak_analytic_n : 0;
    m.rms_angle_deg = m.angle_ticks > 0 ? std::sqrt(sa / static_cast<double>(m.angle_ticks)) : 0;
    if (c.validate_rms_pct && !(m.rms_error_pct <= *c.validate_rms_pct))
      m.failures.push_back(fmt::format("Fig. 9 validation: force RMS error {:.3f} % of peak > {} %", m.rms_error_pct,
                                       *c.validate_rms_pct));
    if (c.validate_angle_deg && !(m.rms_angle_deg <= *c.validate_angle_deg))
      m.failures.push_back(
          fmt::format("Fig. 9 validation: direction RMS error {:.3f}° > {}°", m.rms_angle_deg, *c.validate_angle_deg));
  }
  return m;
}

// Per-tick series for the report: t_s, |f|, analytic |f| (sphere; empty otherwise), spring
// |X_h − X_p|, φ(HIP), φ(proxy), analytic HIP depth — metres and newtons.
std::string SeriesCsv(const std::vector<Tick>& ticks, const Case& c, const FieldSampler& field, double k,
                      double max_force) {
  std::string out = "t_s,force_n,analytic_n,spring_m,phi_hip_m,phi_proxy_m,analytic_depth_m\n";
  for (const Tick& t : ticks) {
    const Eigen::Vector3d h(t.hip[0], t.hip[1], t.hip[2]), p(t.proxy[0], t.proxy[1], t.proxy[2]);
    const Eigen::Vector3d f(t.force[0], t.force[1], t.force[2]);
    std::string analytic = ",", depth;
    if (c.sphere_centre_m) {
      const Eigen::Vector3d centre((*c.sphere_centre_m)[0], (*c.sphere_centre_m)[1], (*c.sphere_centre_m)[2]);
      const double d = c.sphere_radius_m - (h - centre).norm();
      analytic = fmt::format("{:.9g},", std::min(k * std::max(0.0, d), max_force));
      depth = fmt::format("{:.9g}", std::max(0.0, d));
    }
    out += fmt::format("{:.9g},{:.9g},{}{:.9g},{:.9g},{:.9g},{}\n", t.t_s, f.norm(), analytic, (h - p).norm(),
                       field.Phi(h), field.Phi(p), depth);
  }
  return out;
}

// ---------------------------------------------------------------- the harness

struct Context {
  Suite suite;
  HilArgs args;
  fs::path palpa, palpad, work, goldens;
  double k = 800, max_force = 8, rate = 1000;
};

std::string FileStamp(const fs::path& p) {
  struct stat st {};
  if (stat(p.c_str(), &st) != 0) return "missing";
  return fmt::format("{}:{}.{}", st.st_size, st.st_mtim.tv_sec, st.st_mtim.tv_nsec);
}

// Builds (or reuses) the field; returns its path.
std::expected<fs::path, std::string> EnsureField(const Context& cx, const std::string& name) {
  const FieldSpec& spec = cx.suite.fields.at(name);
  if (!spec.blob.empty()) return cx.suite.root / spec.blob;
  const fs::path dir = cx.work / "fields";
  fs::create_directories(dir);
  const fs::path blob = dir / (name + ".palpa");
  const std::string work = cx.work.string();
  std::vector<std::vector<std::string>> commands;
  for (const auto& p : spec.prepare) commands.push_back(SplitWords(Replace(p, "{work}", work)));
  auto build = SplitWords(Replace(spec.build, "{work}", work));
  build.insert(build.end(), {"-o", blob.string(), "-q"});
  commands.push_back(build);
  std::string stamp = "palpa " + FileStamp(cx.palpa) + "\n";
  for (const auto& c : commands) stamp += Join(c) + "\n";
  const fs::path stamp_path = dir / (name + ".stamp");
  if (fs::exists(blob) && Slurp(stamp_path) == stamp) return blob;
  for (auto c : commands) {
    c.insert(c.begin(), cx.palpa.string());
    const int rc = Spawn(c, dir / (name + ".log"), dir / (name + ".err"), cx.suite.root);
    if (rc != 0)
      return std::unexpected(
          fmt::format("field {}: `{}` failed (exit {}): {}", name, Join(c), rc, Slurp(dir / (name + ".err"))));
  }
  std::string error;
  if (!WriteText(stamp_path, stamp, error)) return std::unexpected(error);
  return blob;
}

struct Replay {
  int exit_code = -1;
  std::string csv;
  std::vector<Tick> ticks;
  std::string summary_json, stderr_text, device_report;
  double wall_s = 0;
  fs::path dir;
};

std::vector<std::string> PalpadArgv(const Context& cx, const Case& c, const fs::path& field, const fs::path& out,
                                    const fs::path& summary, bool fast) {
  std::vector<std::string> argv = cx.args.emulator;
  argv.push_back(cx.palpad.string());
  const std::vector<std::string> rest = {"--device",
                                         c.device,
                                         "--field",
                                         field.string(),
                                         "--trace",
                                         (cx.suite.hil_dir / c.trace).string(),
                                         "--out",
                                         out.string(),
                                         "--summary-json",
                                         summary.string(),
                                         "--rate",
                                         fmt::format("{}", cx.rate),
                                         "--k",
                                         fmt::format("{}", cx.k),
                                         "--max-force",
                                         fmt::format("{}", cx.max_force)};
  argv.insert(argv.end(), rest.begin(), rest.end());
  if (fast) argv.push_back("--fast");
  // Per-tick timing (and, paced, the HIP recording) leave palpad through its telemetry ring.
  argv.insert(argv.end(), {"--record-timing", (out.parent_path() / "timing.csv").string()});
  if (!fast) argv.insert(argv.end(), {"--record", (out.parent_path() / "recorded.ptb").string()});
  argv.insert(argv.end(), c.palpad.begin(), c.palpad.end());
  return argv;
}

std::expected<Replay, std::string> RunReplay(const Context& cx, const Case& c, const fs::path& field, bool fast) {
  Replay r;
  r.dir = cx.work / "results" / (fast ? "fast" : "realtime") / c.name;
  fs::create_directories(r.dir);
  for (const char* f : {"out.csv", "summary.json", "timing.csv", "recorded.ptb"}) fs::remove(r.dir / f);
  const auto argv = PalpadArgv(cx, c, field, r.dir / "out.csv", r.dir / "summary.json", fast);
  {
    std::string error;
    if (!WriteText(r.dir / "command.txt", Join(argv) + "\n", error)) return std::unexpected(error);
  }
  const auto t0 = std::chrono::steady_clock::now();
  r.exit_code = Spawn(argv, r.dir / "stdout.txt", r.dir / "stderr.txt", cx.suite.root);
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (r.exit_code < 0) return std::unexpected("cannot start " + argv.front());
  r.csv = Slurp(r.dir / "out.csv");
  r.summary_json = Slurp(r.dir / "summary.json");
  r.stderr_text = Slurp(r.dir / "stderr.txt");
  // The Falcon driver's end-of-run counters run on the virtual Falcon's simulated clock: part of
  // the deterministic output.
  std::istringstream lines(r.stderr_text);
  for (std::string line; std::getline(lines, line);)
    if (line.starts_with("palpad: falcon:") || line.starts_with("palpad: virtual falcon:") ||
        line.find("Falcon") != std::string::npos)
      r.device_report += line + "\n";
  auto ticks = ParseOutput(r.csv, (r.dir / "out.csv").string());
  if (!ticks) return std::unexpected(ticks.error());
  r.ticks = std::move(*ticks);
  return r;
}

// A case's `output`: palpad's CSV from elsewhere, measured as if replayed (exit code as expected).
std::expected<Replay, std::string> ReadOutput(const Context& cx, const Case& c, bool fast) {
  Replay r;
  r.dir = cx.work / "results" / (fast ? "fast" : "realtime") / c.name;
  fs::create_directories(r.dir);
  for (const char* f : {"out.csv", "summary.json", "timing.csv", "recorded.ptb"}) fs::remove(r.dir / f);
  const fs::path path = cx.suite.hil_dir / c.output;
  if (!fs::is_regular_file(path)) return std::unexpected(path.string() + ": no such output file");
  r.csv = Slurp(path);
  r.exit_code = c.expect_exit;
  auto ticks = ParseOutput(r.csv, path.string());
  if (!ticks) return std::unexpected(ticks.error());
  r.ticks = std::move(*ticks);
  return r;
}

// Integer counters from palpad's summary JSON (timing fields are not deterministic and are left
// out), as the goldens store them: a number's JSON text, or a string's value.
std::map<std::string, std::string> Counters(const std::string& summary_json) {
  std::map<std::string, std::string> out;
  const Json summary = Json::parse(summary_json, nullptr, /*allow_exceptions=*/false);
  if (!summary.is_object()) return out;
  for (const char* key : {"ticks", "contact_ticks", "force_clamps", "device_errors", "dropped_rows", "estop_events",
                          "estop_ticks", "gpio_errors", "end", "fault"}) {
    const auto it = summary.find(key);
    if (it == summary.end()) continue;
    out[key] = it->is_string() ? it->get<std::string>() : it->dump();
  }
  return out;
}

struct Golden {
  std::string csv_sha256, ticks_sha256;
  std::size_t ticks = 0;
  int exit_code = 0;
  std::map<std::string, std::string> counters;
  std::string device_report;
};

std::string GoldenToml(const Context& cx, const Case& c, const Replay& r, const std::string& trace_sha) {
  toml::table counters;
  for (const auto& [k, v] : Counters(r.summary_json)) counters.insert(k, v);
  toml::table t{{"format", "palpa-hil-golden 1"},
                {"case", c.name},
                {"trace", c.trace},
                {"trace_sha256", trace_sha},
                {"field_build", cx.suite.fields.at(c.field).blob.empty() ? cx.suite.fields.at(c.field).build
                                                                         : "blob " + cx.suite.fields.at(c.field).blob},
                {"device", c.device},
                {"palpad_args", Join(c.palpad)},
                {"k_n_per_m", cx.k},
                {"max_force_n", cx.max_force},
                {"rate_hz", cx.rate},
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

std::expected<Golden, std::string> ReadGolden(const Context& cx, const Case& c) {
  const fs::path p = cx.goldens / (c.name + ".toml");
  if (!fs::exists(p)) return std::unexpected("no golden " + p.string() + " (bless it: palpa hil bless " + c.name + ")");
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

// What changed between the golden and a replay, in one paragraph.
std::string Differences(const Context& cx, const Case& c, const Golden& g, const Replay& r) {
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
  auto gt = DecodeTicks(Slurp(cx.goldens / (c.name + ".ticks.gz")), g.ticks);
  if (!gt) return out + "    " + gt.error() + "\n";
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

// One case's result.json: the case, the metrics and verdict, `extra` (latency figures) and
// palpad's own summary.
Json MetricsJson(const Case& c, const Replay& r, const Metrics& m, const Context& cx, bool fast,
                 const std::string& verdict, const Json& extra) {
  Json j = {{"case", c.name},
            {"mode", fast ? "fast" : "realtime"},
            {"device", c.device},
            {"field", c.field},
            {"trace", c.trace},
            {"why", c.why},
            {"k_n_per_m", cx.k},
            {"max_force_n", cx.max_force},
            {"rate_hz", cx.rate},
            {"exit_code", r.exit_code},
            {"wall_s", r.wall_s},
            {"ticks", m.ticks},
            {"contact_ticks", m.contact_ticks},
            {"max_force_n_seen", m.max_force_n},
            {"max_slope_n", m.max_slope_n},
            {"slope_limit_n", m.slope_limit_n},
            {"releases", m.releases},
            {"max_release_n", m.max_release_n},
            {"worst_slope_excess_n", m.worst_slope_excess_n},
            {"deepest_hip_mm", m.deepest_hip_mm},
            {"holds", m.holds},
            {"longest_hold_ticks", m.longest_hold_ticks},
            {"clear_way_force_ticks", m.clear_way_force_ticks},
            {"drops_inside", m.drops_inside},
            {"off_surface_force_ticks", m.off_surface_force_ticks},
            {"min_proxy_phi_voxels", m.min_proxy_phi_voxels},
            {"energy_j", m.energy_j},
            {"min_passivity_margin_j", m.min_passivity_margin_j}};
  if (m.analytic) {
    j["analytic"] = {{"kind", "sphere"},
                     {"centre_m", *c.sphere_centre_m},
                     {"radius_m", c.sphere_radius_m},
                     {"peak_n", m.peak_analytic_n},
                     {"rms_error_n", m.rms_error_n},
                     {"rms_error_pct", m.rms_error_pct},
                     {"rms_angle_deg", m.rms_angle_deg},
                     {"max_angle_deg", m.max_angle_deg},
                     {"angle_ticks", m.angle_ticks}};
  }
  for (const auto& [key, value] : extra.items()) j[key] = value;
  j["failures"] = m.failures;
  j["verdict"] = verdict;
  Json summary = Json::parse(r.summary_json, nullptr, /*allow_exceptions=*/false);
  j["summary"] = summary.is_discarded() ? Json(nullptr) : std::move(summary);  // none, or not JSON
  return j;
}

struct LoadedField {
  explicit LoadedField(std::vector<std::byte> b) : bytes(std::move(b)) {}
  std::vector<std::byte> bytes;
  blob::FieldView view;
};

int RunCases(Context& cx, const std::string& action) {
  const bool fast = cx.args.mode != "realtime";
  const bool bless = action == "bless";
  std::vector<const Case*> selected;
  for (const Case& c : cx.suite.cases) {
    bool match = cx.args.filter.empty();
    if (bless && !cx.args.names.empty())
      match = std::find(cx.args.names.begin(), cx.args.names.end(), c.name) != cx.args.names.end();
    else if (!cx.args.filter.empty())
      for (const auto& f : SplitWords(Replace(cx.args.filter, ",", " ")))
        match = match || c.name.find(f) != std::string::npos;
    if (!fast && !c.realtime) match = false;
    if (!cx.args.device.empty() && c.device != cx.args.device) match = false;
    if (match) selected.push_back(&c);
  }
  if (bless && cx.args.names.empty() && !cx.args.all) {
    fmt::print(stderr, "palpa hil bless: name the cases to bless, or --all\n");
    return kExitBadInput;
  }
  if (bless)
    for (const auto& n : cx.args.names)
      if (std::none_of(cx.suite.cases.begin(), cx.suite.cases.end(), [&](const Case& c) { return c.name == n; })) {
        fmt::print(stderr, "palpa hil bless: no case named '{}' in {}\n", n, cx.suite.cases_path.string());
        return kExitBadInput;
      }
  if (selected.empty()) {
    fmt::print(stderr, "palpa hil: no case matches '{}'\n", cx.args.filter);
    return kExitBadInput;
  }
  fmt::print("palpa hil {} ({}): {} case(s), palpad {}{}, k {} N/m, max force {} N, rate {} Hz\n", action,
             fast ? "fast, lockstep" : "realtime, paced", selected.size(), cx.palpad.string(),
             cx.args.emulator.empty() ? "" : " under " + Join(cx.args.emulator), cx.k, cx.max_force, cx.rate);
  int failed = 0;
  std::string index = "[";
  std::map<std::string, std::unique_ptr<LoadedField>> loaded_fields;
  std::vector<std::int64_t> all_wake, all_compute, all_total;
  for (const Case* cp : selected) {
    const Case& c = *cp;
    auto field = EnsureField(cx, c.field);
    if (!field) {
      fmt::print(stderr, "palpa hil: {}\n", field.error());
      return kExitBadInput;
    }
    const fs::path trace_path = cx.suite.hil_dir / c.trace;
    if (auto tr = trace::ReadTraceFile(trace_path.string()); !tr) {
      fmt::print(stderr, "palpa hil: case {}: {}\n", c.name, tr.error().message);
      return kExitBadInput;
    }
    // A swap case replays with --swap-at TICK:PATH; the goldens keep the case's own arguments
    // (the path depends on the work directory).
    Case with_swap = c;
    if (!c.swap_field.empty()) {
      auto swap = EnsureField(cx, c.swap_field);
      if (!swap) {
        fmt::print(stderr, "palpa hil: {}\n", swap.error());
        return kExitBadInput;
      }
      with_swap.palpad.insert(with_swap.palpad.end(), {"--swap-at", fmt::format("{}:{}", c.swap_at, swap->string())});
    }
    auto replay = c.output.empty() ? RunReplay(cx, with_swap, *field, fast) : ReadOutput(cx, c, fast);
    if (!replay) {
      fmt::print(stderr, "palpa hil: case {}: {}\n", c.name, replay.error());
      return kExitBadInput;
    }
    // Each field is read and verified once per run (the sphere's is 108 MB).
    const auto load = [&](const std::string& name, const fs::path& path) -> const LoadedField* {
      auto& loaded = loaded_fields[name];
      if (loaded) return loaded.get();
      auto blob_bytes = blob::ReadFile(path.c_str(), blob::Load::kAsStored);  // v2 sampled in place
      if (!blob_bytes) {
        fmt::print(stderr, "palpa hil: {}\n", blob_bytes.error().what());
        return nullptr;
      }
      loaded = std::make_unique<LoadedField>(std::move(*blob_bytes));
      auto view = blob::Verify(loaded->bytes);
      if (!view) {
        fmt::print(stderr, "palpa hil: {}: {}\n", path.string(), view.error().what());
        loaded.reset();
        return nullptr;
      }
      loaded->view = *view;
      return loaded.get();
    };
    const LoadedField* loaded = load(c.field, *field);
    if (loaded == nullptr) return kExitBadInput;
    const FieldSampler sampler(loaded->view);
    std::optional<FieldSampler> swap_sampler;
    if (!c.swap_field.empty()) {
      const LoadedField* swap_loaded = load(c.swap_field, cx.work / "fields" / (c.swap_field + ".palpa"));
      if (swap_loaded == nullptr) return kExitBadInput;
      swap_sampler.emplace(swap_loaded->view);
    }
    // Timing and telemetry flags from palpad --record-timing (both modes).
    const auto timing = ReadTiming(replay->dir / "timing.csv");
    for (std::size_t i = 0; i < timing.size() && i < replay->ticks.size(); ++i)
      replay->ticks[i].flags = static_cast<std::uint8_t>(timing[i].flags & record::kDeterministicFlags);
    Metrics m = Measure(replay->ticks, c, sampler, swap_sampler ? &*swap_sampler : nullptr, cx.k, cx.max_force,
                        cx.suite.limits);
    if (replay->exit_code != c.expect_exit)
      m.failures.push_back(fmt::format("palpad exited {} (expected {}): {}", replay->exit_code, c.expect_exit,
                                       Replace(replay->stderr_text.substr(0, 400), "\n", " | ")));
    std::string recorded_note;
    std::size_t estop_ticks = 0, estop_force_ticks = 0;
    std::vector<std::int64_t> wake, compute, total;
    for (std::size_t i = 0; i < timing.size(); ++i) {
      wake.push_back(timing[i].wake_ns);
      compute.push_back(timing[i].compute_ns);
      total.push_back(timing[i].total_ns);
      if ((timing[i].flags & record::kFlagEstop) != 0 && i < replay->ticks.size()) {
        ++estop_ticks;
        const auto& f = replay->ticks[i].force;
        if (f[0] != 0 || f[1] != 0 || f[2] != 0) ++estop_force_ticks;
      }
    }
    if (estop_force_ticks > 0)
      m.failures.push_back(
          fmt::format("e-stop asserted on {} ticks, {} of them with non-zero force", estop_ticks, estop_force_ticks));
    if (estop_ticks == 0 && std::ranges::find(c.palpad, "--estop") != c.palpad.end())
      m.failures.push_back("the case wires an e-stop but no tick saw it asserted");
    if (!c.swap_field.empty()) {
      const auto swapped =
          std::ranges::find_if(timing, [](const auto& t) { return (t.flags & record::kFlagSwap) != 0; });
      if (swapped == timing.end())
        m.failures.push_back(
            fmt::format("the case swaps to field {} at tick {}, but no tick took it", c.swap_field, c.swap_at));
      else if (swapped - timing.begin() != c.swap_at)
        m.failures.push_back(
            fmt::format("the field swap landed on tick {}, not tick {}", swapped - timing.begin(), c.swap_at));
    }
    const Percentiles pw = Figures(wake), pc = Figures(compute), pt = Figures(total);
    all_wake.insert(all_wake.end(), wake.begin(), wake.end());
    all_compute.insert(all_compute.end(), compute.begin(), compute.end());
    all_total.insert(all_total.end(), total.begin(), total.end());
    // --record (paced runs): the recording must read and hold the HIP the loop saw, tick by tick.
    if (!fast) {
      auto rec = trace::ReadTraceFile((replay->dir / "recorded.ptb").string());
      if (!rec) {
        m.failures.push_back("--record: " + rec.error().message);
      } else {
        const auto dropped = static_cast<std::size_t>(std::max<std::int64_t>(
            0, static_cast<std::int64_t>(replay->ticks.size()) - static_cast<std::int64_t>(rec->samples.size())));
        std::size_t off = 0;
        for (std::size_t i = 0, j = 0; i < rec->samples.size() && j < replay->ticks.size(); ++j) {
          if (std::abs(rec->samples[i].t_s - replay->ticks[j].t_s) > 1e-9) continue;  // a dropped sample
          for (std::size_t a = 0; a < 3; ++a)
            if (std::abs(rec->samples[i].hip_m[a] - replay->ticks[j].hip[a]) > 1e-9) ++off;
          ++i;
        }
        if (off > 0)
          m.failures.push_back(fmt::format("--record: {} coordinates differ from the HIP the loop read", off));
        recorded_note = fmt::format("recorded {} of {} HIP samples ({} dropped)", rec->samples.size(),
                                    replay->ticks.size(), dropped);
      }
    }
    std::vector<std::string> known, gone;
    for (const auto& x : c.xfail) {
      const auto it = std::find_if(m.failures.begin(), m.failures.end(),
                                   [&](const std::string& f) { return f.find(x) != std::string::npos; });
      if (it == m.failures.end()) {
        gone.push_back(x);
      } else {
        known.push_back(*it);
        m.failures.erase(it);
      }
    }
    std::string verdict = m.failures.empty() ? "ok" : "FAIL";
    std::string detail;
    const std::string trace_sha = Sha256Hex(Slurp(trace_path));
    if (fast && !bless) {
      auto g = ReadGolden(cx, c);
      if (!g) {
        verdict = "NO GOLDEN";
        detail = "    " + g.error() + "\n";
      } else if (g->csv_sha256 != Sha256Hex(replay->csv) || g->ticks_sha256 != Sha256Hex(RawTicks(replay->ticks)) ||
                 g->exit_code != replay->exit_code || g->device_report != replay->device_report ||
                 g->counters != Counters(replay->summary_json)) {
        verdict = "MISMATCH";
        detail = Differences(cx, c, *g, *replay);
      }
    }
    if (bless) {
      auto old = ReadGolden(cx, c);
      std::string error;
      fs::create_directories(cx.goldens);
      const std::string gz = EncodeTicks(replay->ticks);
      std::string what = "new golden";
      if (old) {
        if (old->csv_sha256 == Sha256Hex(replay->csv) && old->ticks_sha256 == Sha256Hex(RawTicks(replay->ticks)) &&
            old->exit_code == replay->exit_code && old->device_report == replay->device_report &&
            old->counters == Counters(replay->summary_json))
          what = "unchanged";
        else
          what = "changed:\n" + Differences(cx, c, *old, *replay);
      }
      if (!WriteText(cx.goldens / (c.name + ".ticks.gz"), gz, error) ||
          !WriteText(cx.goldens / (c.name + ".toml"), GoldenToml(cx, c, *replay, trace_sha), error)) {
        fmt::print(stderr, "palpa hil bless: {}\n", error);
        return kExitIo;
      }
      detail = "    " + what + (what.ends_with("\n") ? "" : "\n");
      verdict = m.failures.empty() ? "blessed" : "blessed (FAILS invariants)";
    }
    if (verdict != "ok" && verdict != "blessed") ++failed;
    fmt::print("  {:<32} {:<14} {:>6} ticks {:>6} contact  max |f| {:7.3f} N  φmin {:+.3f} vx  {:6.2f} s  {}\n", c.name,
               c.device, m.ticks, m.contact_ticks, m.max_force_n, m.min_proxy_phi_voxels, replay->wall_s, verdict);
    if (m.analytic)
      fmt::print(
          "      sphere (Fig. 9): peak {:.3f} N, force RMS error {:.4f} N = {:.3f} % of peak, direction RMS "
          "{:.3f}° (max {:.3f}°, {} ticks)\n",
          m.peak_analytic_n, m.rms_error_n, m.rms_error_pct, m.rms_angle_deg, m.max_angle_deg, m.angle_ticks);
    if (!fast)
      fmt::print(
          "      latency (µs, {} ticks): wake-up p50 {:.1f} p99 {:.1f} p99.9 {:.1f} max {:.1f}; compute p50 {:.1f} "
          "p99 {:.1f} max {:.1f}; total p99 {:.1f} max {:.1f}; {}\n",
          pw.count, pw.p50, pw.p99, pw.p999, pw.max, pc.p50, pc.p99, pc.max, pt.p99, pt.max, recorded_note);
    fmt::print(
        "      deepest HIP {:.2f} mm, worst slope excess {:+.4f} N, releases {} (largest {:.3f} N), holds {} "
        "(longest {} ticks)\n",
        m.deepest_hip_mm, m.ticks > 1 ? m.worst_slope_excess_n : 0.0, m.releases, m.max_release_n, m.holds,
        m.longest_hold_ticks);
    for (const auto& f : m.failures) fmt::print("    invariant: {}\n", f);
    for (const auto& f : known) fmt::print("    known failure (xfail in cases.toml): {}\n", f);
    for (const auto& x : gone)
      fmt::print("    xfail '{}' no longer occurs: remove it from {}\n", x, cx.suite.cases_path.string());
    fmt::print("{}", detail);
    std::string error;
    if (!WriteText(replay->dir / "series.csv", SeriesCsv(replay->ticks, c, sampler, cx.k, cx.max_force), error))
      fmt::print(stderr, "palpa hil: {}\n", error);
    auto fig = [](const Percentiles& p) {
      return Json{{"count", p.count}, {"p50_us", p.p50}, {"p99_us", p.p99}, {"p999_us", p.p999}, {"max_us", p.max}};
    };
    const Json extra = {{"latency", {{"wake", fig(pw)}, {"compute", fig(pc)}, {"total", fig(pt)}}},
                        {"estop_ticks", estop_ticks}};
    // (A path or message that is not UTF-8 is written with U+FFFD rather than failing the run.)
    const std::string json =
        MetricsJson(c, *replay, m, cx, fast, verdict, extra).dump(-1, ' ', false, Json::error_handler_t::replace);
    if (!WriteText(replay->dir / "result.json", json + "\n", error)) fmt::print(stderr, "palpa hil: {}\n", error);
    index += (index.size() > 1 ? ",\n" : "\n") + json;  // one case a line
  }
  index += "\n]\n";
  std::string error;
  const fs::path index_path = cx.work / "results" / (fast ? "fast" : "realtime") / "index.json";
  if (!WriteText(index_path, index, error)) fmt::print(stderr, "palpa hil: {}\n", error);
  if (!fast) {
    const Percentiles w = Figures(all_wake), c = Figures(all_compute), t = Figures(all_total);
    fmt::print("latency over all {} ticks at {} Hz (µs):\n", w.count, cx.rate);
    fmt::print("  {:<16} {:>8} {:>8} {:>8} {:>9}\n", "", "p50", "p99", "p99.9", "max");
    for (const auto& [name, p] : {std::pair{"wake-up latency", w}, std::pair{"compute", c}, std::pair{"total", t}})
      fmt::print("  {:<16} {:>8.1f} {:>8.1f} {:>8.1f} {:>9.1f}\n", name, p.p50, p.p99, p.p999, p.max);
  }
  fmt::print("{} passed, {} failed\n", selected.size() - static_cast<std::size_t>(failed), failed);
  return failed == 0 ? kExitOk : kExitFailed;
}

}  // namespace

int RunHil(const HilArgs& args, const std::string& action) {
  Context cx;
  cx.args = args;
  std::optional<fs::path> cases = args.cases.empty() ? FindCases() : std::optional<fs::path>(args.cases);
  if (!cases) {
    fmt::print(stderr, "palpa hil: no hil/cases.toml above the current directory (use --cases)\n");
    return kExitBadInput;
  }
  auto suite = LoadSuite(*cases);
  if (!suite) {
    fmt::print(stderr, "palpa hil: {}\n", suite.error());
    return kExitBadInput;
  }
  cx.suite = std::move(*suite);
  cx.palpa = SelfExe();
  if (!args.palpad.empty()) {
    cx.palpad = fs::absolute(args.palpad);
  } else {
    const fs::path dir = cx.palpa.parent_path();
    for (const fs::path& p : {dir / "palpad", dir / ".." / ".." / "firmware" / "palpad"})
      if (fs::exists(p)) {
        cx.palpad = fs::canonical(p);
        break;
      }
  }
  if (cx.palpad.empty() || !fs::exists(cx.palpad)) {
    fmt::print(stderr, "palpa hil: palpad not found next to {} (use --palpad)\n", cx.palpa.string());
    return kExitBadInput;
  }
  cx.work = fs::absolute(args.work.empty() ? cx.suite.root / "build" / "hil-work" : fs::path(args.work));
  cx.goldens = fs::absolute(args.goldens.empty() ? cx.suite.hil_dir / "goldens" : fs::path(args.goldens));
  cx.k = args.k.value_or(cx.suite.k_n_per_m);
  cx.max_force = args.max_force.value_or(cx.suite.max_force_n);
  cx.rate = args.rate.value_or(cx.suite.rate_hz);
  if (action == "bless" &&
      (args.k || args.max_force || args.rate || !args.emulator.empty() || args.mode == "realtime")) {
    fmt::print(stderr, "palpa hil bless: goldens are blessed with the cases' own settings, natively, in fast mode\n");
    return kExitBadInput;
  }
  std::error_code ec;
  fs::create_directories(cx.work, ec);
  if (ec) {
    fmt::print(stderr, "palpa hil: cannot create {}: {}\n", cx.work.string(), ec.message());
    return kExitIo;
  }
  if (action == "report") {
    HilArgs run_args = args;
    cx.args = run_args;
    const int rc = RunCases(cx, "run");
    if (rc == kExitBadInput || rc == kExitIo) return rc;
    const fs::path results = cx.work / "results" / (args.mode == "realtime" ? "realtime" : "fast");
    const fs::path script = cx.suite.root / "scripts" / "hil-report.py";
    const std::vector<std::string> argv = {"/usr/bin/python3",
                                           script.string(),
                                           "--results",
                                           results.string(),
                                           "-o",
                                           fs::absolute(args.report_dir).string()};
    const int py = Spawn(argv, cx.work / "report.log", cx.work / "report.err", cx.suite.root);
    fmt::print("{}", Slurp(cx.work / "report.log"));
    if (py != 0) {
      fmt::print(stderr, "palpa hil report: {} failed (exit {}):\n{}", script.string(), py,
                 Slurp(cx.work / "report.err"));
      return kExitIo;
    }
    return rc;
  }
  return RunCases(cx, action);
}

}  // namespace palpa::cli
