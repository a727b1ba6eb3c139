// The goldens of fast replays (docs/hil.md § Fast (lockstep) mode and goldens): per case NAME.toml
// (SHA-256 digests of palpad's CSV and of the tick stream, tick count, exit code, run counters,
// the Falcon report, the settings and inputs it was blessed with) and NAME.ticks.gz (the tick
// stream: per tick the force as zigzag-varint deltas in 2^-24 N, contact, flags, row hash; gzip).
// Encoding, decoding, reading, comparing; writing the files is the caller's (palpa hil bless).
#pragma once

#include <cstddef>
#include <expected>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "palpa/hil/replay.h"
#include "palpa/hil/suite.h"

namespace palpa::hil {

/// SHA-256 of `bytes`, 64 lower-case hex digits (nettle).
[[nodiscard]] std::string Sha256Hex(std::string_view bytes);
/// SHA-256 of a file's bytes (a golden's trace_sha256); of no bytes if it cannot be read.
[[nodiscard]] std::string Sha256HexOfFile(const std::filesystem::path& p);

/// The uncompressed tick stream: per tick three zigzag varints (force x, y, z in 2^-24 N, each the
/// delta from the previous tick's), then four bytes: contact 0/1, flags, row hash low, high.
/// Its SHA-256 is a golden's ticks_sha256.
[[nodiscard]] std::string RawTicks(const std::vector<Tick>& ticks);
/// RawTicks gzip-compressed (level 9, mtime 0: the same ticks give the same bytes): NAME.ticks.gz.
[[nodiscard]] std::string EncodeTicks(const std::vector<Tick>& ticks);
/// The first `count` ticks of an EncodeTicks stream: forces (force_q24 and newtons), contact,
/// flags and row hashes; t_s, HIP and proxy are not stored (0). Error: names the byte, "corrupt
/// golden tick stream (gzip) at byte N of SIZE: zlib's reason" (N where zlib stopped: at or after
/// the damage) or "golden tick stream ends early: tick I of COUNT needs byte B of SIZE
/// (uncompressed)".
[[nodiscard]] std::expected<std::vector<Tick>, std::string> DecodeTicks(std::string_view gz, std::size_t count);

/// palpad's summary JSON reduced to its deterministic counters (ticks, contact_ticks,
/// force_clamps, device_errors, dropped_rows, estop_events, estop_ticks, gpio_errors, end, fault;
/// timing is left out), each as a number's JSON text or a string's value. Not JSON: none.
[[nodiscard]] std::map<std::string, std::string> Counters(const std::string& summary_json);

/// What a NAME.toml holds that a replay must reproduce.
struct Golden {
  std::string csv_sha256, ticks_sha256;
  std::size_t ticks = 0;
  int exit_code = 0;
  std::map<std::string, std::string> counters;
  std::string device_report;
};

/// DIR/NAME.toml and DIR/NAME.ticks.gz.
[[nodiscard]] std::filesystem::path GoldenTomlPath(const std::filesystem::path& dir, const std::string& name);
[[nodiscard]] std::filesystem::path GoldenTicksPath(const std::filesystem::path& dir, const std::string& name);

/// NAME.toml's text for a replay of case `c` with `settings` on a field made as `field`; the
/// trace's SHA-256 records which trace it was blessed with.
[[nodiscard]] std::string GoldenToml(const Case& c, const FieldSpec& field, const Settings& settings, const Replay& r,
                                     const std::string& trace_sha256);

/// Reads DIR/NAME.toml. Error: "no golden PATH (bless it: palpa hil bless NAME)", or
/// "PATH:LINE: why" for TOML syntax.
[[nodiscard]] std::expected<Golden, std::string> ReadGolden(const std::filesystem::path& dir, const std::string& name);

/// Both digests, the exit code, the device report and the counters all match.
[[nodiscard]] bool Reproduces(const Golden& g, const Replay& r);

/// What changed between golden `g` (its tick stream in `dir`) and replay `r`: one indented line
/// per differing item (exit code, ticks, each counter, device report), then the ticks changed (and
/// on how many the force changed), the first changed tick and the largest force difference in N
/// with its tick. An unreadable tick stream ends the paragraph with its error.
[[nodiscard]] std::string Differences(const std::filesystem::path& dir, const std::string& name, const Golden& g,
                                      const Replay& r);

}  // namespace palpa::hil
