// HIP traces: the recorded or synthesised path of the haptic interface point that a simulated
// device (or the virtual Falcon's hand) replays, that `palpa trace synth` writes and that
// `palpad --record` records. docs/trace-format.md is the specification. Non-RT (parsing, files);
// the servo loop reads the parsed samples from memory allocated at start-up (HipAt is RT-safe).
//
// Format v2 has two encodings of the same samples:
//
//  text    # palpa-trace v2 units=s,m frame=device columns=t_s,x_m,y_m,z_m[,buttons]   (line 1)
//          # free comment lines, blank lines
//          0.000000000,0.001000000,-0.002000000,0.012000000[,0]
//
//  binary  byte 0          64            64 + C         64 + C + N·R
//          +-- header ----+-- comment --+-- records ---+
//          | see TraceBinaryHeader      | dt_ns u32, x,y,z i32 nm [, buttons u8] |
//          little-endian; CRC-32C over header bytes [0, 60) then comment and records.
//
// v1 (no header line, rows t_s,x_m,y_m,z_m, optional column line) is still read: the shim.
// Every version is checked the same way: time strictly increasing, values finite, HIP inside
// the Falcon workspace (kFalconWorkspace), at least 2 samples. Errors name file and line (text)
// or file and byte (binary).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <expected>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace palpa::trace {

/// One HIP sample. Device frame (the frame of the blob's origin_m), SI units.
struct TraceSample {
  double t_s = 0;                 ///< time, s (any start; strictly increasing)
  std::array<double, 3> hip_m{};  ///< HIP position, m
  std::uint8_t buttons = 0;       ///< button bitmask (Falcon: bits 0-3); 0 when the trace has none
};

/// An axis-aligned box in the device frame, m.
struct Workspace {
  std::array<double, 3> min_m{};
  std::array<double, 3> max_m{};
  /// True if every coordinate is within [min, max] (NaN is outside).
  constexpr bool Contains(const std::array<double, 3>& p) const {
    for (std::size_t i = 0; i < 3; ++i)
      if (!(p[i] >= min_m[i] && p[i] <= max_m[i])) return false;
    return true;
  }
};

/// Where a Falcon HIP can be, device frame (= Falcon frame − (0, 0, 0.125) m, docs/falcon.md §4):
/// a 12 cm cube around the workspace origin. It holds the grip's documented z range 0.075..0.175
/// m (±5 cm) and the ±6 cm x/y range over which the kinematics were checked, with 1 cm to spare
/// in z; a sample outside it cannot have come from a Falcon and is refused.
inline constexpr Workspace kFalconWorkspace{{-0.06, -0.06, -0.06}, {0.06, 0.06, 0.06}};

/// A parse failure: `line` is the 1-based text line (0 for file-level and binary errors),
/// `byte` the byte offset of a binary error; `message` names the file and line or byte.
struct TraceError {
  std::size_t line = 0;
  std::size_t byte = 0;
  std::string message;
};

/// What a trace file held besides its samples.
struct TraceInfo {
  int version = 2;           ///< 1 (shim) or 2
  bool binary = false;       ///< binary encoding
  bool has_buttons = false;  ///< a buttons column / flag was present
  std::string comment;       ///< v2: comment lines (text, without "# ") or the binary comment, '\n'-joined
};

struct TraceFile {
  std::vector<TraceSample> samples;
  TraceInfo info;
};

// ---- binary encoding ----

inline constexpr std::array<char, 8> kBinaryMagic = {'P', 'A', 'L', 'P', 'A', 'T', 'R', 'C'};
inline constexpr std::uint16_t kVersion = 2;
inline constexpr std::uint16_t kBinaryHeaderSize = 64;
inline constexpr std::uint16_t kFlagButtons = 1;          ///< records carry a buttons byte
inline constexpr std::uint32_t kMaxCommentBytes = 65536;  ///< comment length limit
inline constexpr double kPositionLsbM = 1e-9;             ///< binary (and v2 text writer) resolution: 1 nm
inline constexpr double kTimeLsbS = 1e-9;                 ///< 1 ns

/// The binary header exactly as stored (little-endian). Comments: size (offset) meaning.
struct TraceBinaryHeader {
  std::array<char, 8> magic;    // 8B (0)   "PALPATRC"
  std::uint16_t version;        // 2B (8)   2
  std::uint16_t flags;          // 2B (10)  kFlagButtons or 0; other bits rejected
  std::uint16_t header_size;    // 2B (12)  64
  std::uint16_t record_size;    // 2B (14)  16, or 17 with kFlagButtons
  std::uint64_t sample_count;   // 8B (16)  ≥ 2
  std::int64_t t0_ns;           // 8B (24)  time of sample 0, ns
  std::uint32_t comment_bytes;  // 4B (32)  UTF-8 comment after the header, ≤ kMaxCommentBytes
  std::uint32_t reserved0;      // 4B (36)  0
  std::uint64_t payload_size;   // 8B (40)  comment_bytes + sample_count·record_size = file size − 64
  std::uint64_t reserved1;      // 8B (48)  0
  std::uint32_t reserved2;      // 4B (56)  0
  std::uint32_t crc32c;         // 4B (60)  CRC-32C of bytes [0, 60) then the payload
};
static_assert(sizeof(TraceBinaryHeader) == kBinaryHeaderSize);
static_assert(offsetof(TraceBinaryHeader, flags) == 10 && offsetof(TraceBinaryHeader, record_size) == 14);
static_assert(offsetof(TraceBinaryHeader, sample_count) == 16 && offsetof(TraceBinaryHeader, t0_ns) == 24);
static_assert(offsetof(TraceBinaryHeader, comment_bytes) == 32 && offsetof(TraceBinaryHeader, payload_size) == 40);
static_assert(offsetof(TraceBinaryHeader, crc32c) == 60);
/// Record: dt_ns u32 (0 for sample 0, > 0 after), x, y, z int32 nm, then buttons u8 if flagged.
inline constexpr std::uint16_t kRecordSize = 16;

// ---- reading ----

/// The largest trace file read: 1 GiB (256 MiB where size_t has 32 bits); an hour of text
/// samples at 1 kHz is about 200 MB.
inline constexpr std::uint64_t kMaxTraceFileBytes =
    sizeof(std::size_t) >= 8 ? std::uint64_t{1} << 30 : std::uint64_t{256} << 20;

/// Reads a trace file of any version and encoding (binary by its magic, else text). Only a
/// regular file of at most kMaxTraceFileBytes (io::ReadBounded); errors name the file.
[[nodiscard]] std::expected<TraceFile, TraceError> ReadTraceFile(const std::string& path);

/// ReadTraceFile, samples only (what palpad's devices take).
[[nodiscard]] std::expected<std::vector<TraceSample>, TraceError> ReadTrace(const std::string& path);

/// Parses trace bytes (binary by magic, else text v2 or v1); `name` is used in messages.
[[nodiscard]] std::expected<TraceFile, TraceError> ParseTraceBytes(std::span<const std::byte> bytes,
                                                                   const std::string& name);

/// Parses trace text (v2 with its header line, else v1); samples only.
[[nodiscard]] std::expected<std::vector<TraceSample>, TraceError> ParseTrace(const std::string& text,
                                                                             const std::string& name);

// ---- writing ----

/// Formats a v2 text trace: the header line (with the buttons column if `buttons` or any sample
/// has buttons), each line of `comment` as a `# ` line, then one row per sample with time and
/// positions to 9 decimals (1 ns, 1 nm: the values the binary encoding would store, so both
/// encodings read back to the same doubles). Samples are written as given; validate them with
/// CheckSamples first if they may be bad.
[[nodiscard]] std::string FormatTrace(const std::vector<TraceSample>& samples, const std::string& comment,
                                      bool buttons = false);

/// Encodes the binary form. Errors (named sample index): CheckSamples' errors, two samples less
/// than 1 ns apart, a gap ≥ 2^32 ns (4.29 s), a comment over kMaxCommentBytes.
[[nodiscard]] std::expected<std::string, TraceError> EncodeBinaryTrace(const std::vector<TraceSample>& samples,
                                                                       const std::string& comment,
                                                                       bool buttons = false);

/// The checks every reader applies, for writers: ≥ 2 samples, finite, strictly increasing
/// time, inside kFalconWorkspace. The error names the 0-based sample index.
[[nodiscard]] std::expected<void, TraceError> CheckSamples(const std::vector<TraceSample>& samples);

/// Writes a trace sample by sample to a stdio stream, in either encoding: what `palpad --record`
/// uses, on its non-RT drain thread, so a recording of any length needs no memory. Samples the
/// format cannot hold (outside the workspace, not finite, time not increasing by ≥ 1 ns, a gap
/// ≥ 4.29 s in the binary form) are skipped and counted in refused(), so the file always reads.
/// Binary: the header is written last (Finish seeks back), its CRC read back from the file.
/// The stream must be seekable and readable for the binary form (open it "w+b"). Non-RT.
class TraceStreamWriter {
 public:
  /// `binary`: binary v2, else text v2. `comment` as in FormatTrace/EncodeBinaryTrace.
  TraceStreamWriter(std::FILE* file, bool binary, std::string comment);
  /// Writes the header (text) or reserves it (binary). False on an I/O error.
  bool Begin();
  /// Appends one sample (buttons are kept: the buttons column / flag is always present). False
  /// if it was refused (counted) or the write failed (io_error()).
  bool Add(const TraceSample& s);
  /// Completes the file (binary: header with count and CRC). Error: a sentence; fewer than 2
  /// samples is an error too (the file would not read).
  std::expected<void, std::string> Finish();

  std::uint64_t written() const { return written_; }
  std::uint64_t refused() const { return refused_; }
  bool io_error() const { return io_error_; }

 private:
  std::FILE* file_;
  bool binary_;
  std::string comment_;
  std::uint64_t written_ = 0, refused_ = 0;
  bool io_error_ = false;
  std::int64_t t0_ns_ = 0, last_ns_ = 0;
};

/// HIP at time t by linear interpolation between samples (clamped to the first/last sample).
/// `hint` is a cursor kept by the caller so that monotonic queries cost O(1) amortised. RT-safe.
std::array<double, 3> HipAt(const std::vector<TraceSample>& samples, double t_s, std::size_t& hint);

}  // namespace palpa::trace
