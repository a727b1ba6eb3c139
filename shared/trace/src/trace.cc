#include "palpa/trace/trace.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>

#include "palpa/blob/blob.h"
#include "palpa/io/escape.h"
#include "palpa/io/file_safety.h"

namespace palpa::trace {
namespace {

constexpr std::string_view kHeaderPrefix = "# palpa-trace ";
constexpr std::string_view kColumns4 = "t_s,x_m,y_m,z_m";
constexpr std::string_view kColumns5 = "t_s,x_m,y_m,z_m,buttons";

std::unexpected<TraceError> FailLine(const std::string& name, std::size_t line, const std::string& what) {
  return std::unexpected(
      TraceError{line, 0, line > 0 ? name + ":" + std::to_string(line) + ": " + what : name + ": " + what});
}

std::unexpected<TraceError> FailByte(const std::string& name, std::size_t byte, const std::string& what) {
  return std::unexpected(TraceError{0, byte, name + ": byte " + std::to_string(byte) + ": " + what});
}

std::string Num(double v) {
  char buf[64];
  const int n = std::snprintf(buf, sizeof buf, "%.9g", v);
  return std::string(buf, n > 0 ? static_cast<std::size_t>(n) : 0);
}

std::string OutsideMessage(const std::array<double, 3>& p) {
  return "HIP (" + Num(p[0]) + ", " + Num(p[1]) + ", " + Num(p[2]) +
         ") m is outside the Falcon workspace (|x|, |y|, |z| <= 0.06 m, device frame)";
}

// Round to the nearest multiple of 1e-9 (ns or nm) as an integer; |v| must be small (checked by
// the callers: times within ±2^53 ns, positions within the workspace).
std::int64_t ToNano(double v) { return std::llround(v * 1e9); }

// "-12.000345678": n·1e-9 printed exactly.
void AppendNano(std::string& out, std::int64_t n) {
  char buf[40];
  const bool negative = n < 0;
  const std::uint64_t a = negative ? 0 - static_cast<std::uint64_t>(n) : static_cast<std::uint64_t>(n);
  const int len =
      std::snprintf(buf, sizeof buf, "%s%llu.%09llu", negative ? "-" : "",
                    static_cast<unsigned long long>(a / 1000000000u), static_cast<unsigned long long>(a % 1000000000u));
  if (len > 0) out.append(buf, static_cast<std::size_t>(len));
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.back() == '\r' || s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  return s;
}

// The checks shared by every reader, for one new sample after `previous` (nullptr for the first).
// Returns an empty string when the sample is good.
std::string SampleProblem(const TraceSample& s, const TraceSample* previous) {
  if (!std::isfinite(s.t_s)) return "time is not finite";
  constexpr const char* kAxisProblem[3] = {"position x is not finite", "position y is not finite",
                                           "position z is not finite"};
  for (std::size_t i = 0; i < 3; ++i)
    if (!std::isfinite(s.hip_m[i])) return kAxisProblem[i];
  if (previous != nullptr && !(s.t_s > previous->t_s))
    return "time " + Num(s.t_s) + " s does not increase (previous " + Num(previous->t_s) + " s)";
  if (!kFalconWorkspace.Contains(s.hip_m)) return OutsideMessage(s.hip_m);
  return {};
}

// Parses the v2 header line's key=value words. Returns the error sentence or empty.
std::string ParseHeader(std::string_view line, TraceInfo& info) {
  line.remove_prefix(kHeaderPrefix.size());
  bool units = false, frame = false, columns = false;
  bool first = true;
  while (!line.empty()) {
    const auto space = line.find(' ');
    const std::string_view word = line.substr(0, space);
    line = space == std::string_view::npos ? std::string_view() : line.substr(space + 1);
    if (word.empty()) continue;
    if (first) {
      first = false;
      if (word != "v2") {
        if (word.size() >= 2 && word[0] == 'v')
          return "trace format " + std::string(word) + " is not supported (this reader knows v1 and v2)";
        return "header line must start with '# palpa-trace v2'";
      }
      continue;
    }
    const auto eq = word.find('=');
    if (eq == std::string_view::npos) return "header word '" + io::Escape(word) + "' is not key=value";
    const std::string_view key = word.substr(0, eq), value = word.substr(eq + 1);
    if (key == "units") {
      if (value != "s,m") return "units must be s,m (seconds, metres), found '" + io::Escape(value) + "'";
      units = true;
    } else if (key == "frame") {
      if (value != "device") return "frame must be device, found '" + io::Escape(value) + "'";
      frame = true;
    } else if (key == "columns") {
      if (value == kColumns4) {
        info.has_buttons = false;
      } else if (value == kColumns5) {
        info.has_buttons = true;
      } else {
        return "columns must be " + std::string(kColumns4) + " or " + std::string(kColumns5) + ", found '" +
               io::Escape(value) + "'";
      }
      columns = true;
    } else {
      return "unknown header key '" + io::Escape(key) + "'";
    }
  }
  if (first) return "header line names no version";
  if (!units) return "header line lacks units=s,m";
  if (!frame) return "header line lacks frame=device";
  if (!columns) return "header line lacks columns=";
  return {};
}

std::expected<TraceFile, TraceError> ParseText(std::string_view text, const std::string& name) {
  TraceFile file;
  file.info.version = 1;
  std::size_t line_no = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view raw(text.data() + pos, end - pos);
    pos = end + 1;
    ++line_no;
    const std::string_view line = Trim(raw);
    if (line_no == 1 && line.starts_with(kHeaderPrefix.substr(0, kHeaderPrefix.size() - 1))) {
      if (!line.starts_with(kHeaderPrefix)) return FailLine(name, line_no, "malformed header line");
      if (const std::string problem = ParseHeader(line, file.info); !problem.empty())
        return FailLine(name, line_no, problem);
      file.info.version = 2;
      continue;
    }
    if (line.empty()) continue;
    if (line.front() == '#') {
      if (file.info.version == 2) {
        std::string_view c = line.substr(1);
        if (!c.empty() && c.front() == ' ') c.remove_prefix(1);
        if (!file.info.comment.empty()) file.info.comment += '\n';
        file.info.comment.append(c);
      }
      continue;
    }
    const bool buttons = file.info.has_buttons;
    const std::size_t want = buttons ? 5 : 4;
    const std::string_view columns = buttons ? kColumns5 : kColumns4;
    if (line.starts_with("t_s")) {
      if (line != columns)
        return FailLine(name, line_no, "unknown column line (expected " + std::string(columns) + ")");
      continue;
    }
    double v[5] = {};
    std::size_t count = 0;
    const char* p = line.data();
    const char* stop = line.data() + line.size();
    while (p < stop) {
      while (p < stop && (*p == ' ' || *p == '\t')) ++p;
      if (count == want)
        return FailLine(name, line_no,
                        "more than " + std::to_string(want) + " values (expected " + std::string(columns) + ")");
      if (count == 4) {
        unsigned b = 0;
        const auto [next, ec] = std::from_chars(p, stop, b);
        if (ec != std::errc() || b > 255) return FailLine(name, line_no, "buttons must be an integer 0..255");
        v[count++] = b;
        p = next;
      } else {
        double x = 0;
        const auto [next, ec] = std::from_chars(p, stop, x);
        if (ec != std::errc())
          return FailLine(name, line_no, "value " + std::to_string(count + 1) + " is not a number");
        v[count++] = x;
        p = next;
      }
      while (p < stop && (*p == ' ' || *p == '\t')) ++p;
      if (p < stop) {
        if (*p != ',') return FailLine(name, line_no, "expected ',' after value " + std::to_string(count));
        ++p;
        if (p == stop) return FailLine(name, line_no, "trailing ','");
      }
    }
    if (count != want)
      return FailLine(
          name, line_no,
          "expected " + std::to_string(want) + " values " + std::string(columns) + ", found " + std::to_string(count));
    TraceSample s{v[0], {v[1], v[2], v[3]}, static_cast<std::uint8_t>(v[4])};
    if (const std::string problem = SampleProblem(s, file.samples.empty() ? nullptr : &file.samples.back());
        !problem.empty())
      return FailLine(name, line_no, problem);
    file.samples.push_back(s);
  }
  if (file.samples.size() < 2)
    return FailLine(name, 0, "a trace needs at least 2 samples, found " + std::to_string(file.samples.size()));
  return file;
}

template <typename T>
T Load(std::span<const std::byte> bytes, std::size_t offset) {
  T v;
  std::memcpy(&v, bytes.data() + offset, sizeof v);
  return v;
}

std::expected<TraceFile, TraceError> ParseBinary(std::span<const std::byte> bytes, const std::string& name) {
  if (bytes.size() < kBinaryHeaderSize)
    return FailByte(name, bytes.size(), "binary trace shorter than its 64-byte header");
  TraceBinaryHeader h;
  std::memcpy(&h, bytes.data(), sizeof h);
  if (h.magic != kBinaryMagic) return FailByte(name, 0, "not a palpa binary trace (magic)");
  if (h.version != kVersion)
    return FailByte(name, offsetof(TraceBinaryHeader, version),
                    "binary trace version " + std::to_string(h.version) + " is not supported (this reader knows 2)");
  if ((h.flags & ~kFlagButtons) != 0)
    return FailByte(name, offsetof(TraceBinaryHeader, flags), "unknown flags " + std::to_string(h.flags));
  if (h.header_size != kBinaryHeaderSize)
    return FailByte(name, offsetof(TraceBinaryHeader, header_size), "header size must be 64");
  const bool buttons = (h.flags & kFlagButtons) != 0;
  const std::size_t record = kRecordSize + (buttons ? 1u : 0u);
  if (h.record_size != record)
    return FailByte(
        name, offsetof(TraceBinaryHeader, record_size),
        "record size " + std::to_string(h.record_size) + " does not match the flags (" + std::to_string(record) + ")");
  if (h.reserved0 != 0 || h.reserved1 != 0 || h.reserved2 != 0)
    return FailByte(name, offsetof(TraceBinaryHeader, reserved0), "reserved fields must be zero");
  if (h.comment_bytes > kMaxCommentBytes)
    return FailByte(name, offsetof(TraceBinaryHeader, comment_bytes), "comment longer than 65536 bytes");
  const std::size_t payload = bytes.size() - kBinaryHeaderSize;
  if (h.payload_size != payload)
    return FailByte(name, offsetof(TraceBinaryHeader, payload_size),
                    "payload size " + std::to_string(h.payload_size) + " but the file holds " +
                        std::to_string(payload) + " bytes after the header");
  // Overflow-free: count ≤ (payload − comment) / record, and equality of the product.
  if (h.comment_bytes > payload || h.sample_count > (payload - h.comment_bytes) / record ||
      h.sample_count * record != payload - h.comment_bytes)
    return FailByte(name, offsetof(TraceBinaryHeader, sample_count),
                    "sample count " + std::to_string(h.sample_count) + " does not fill the payload");
  if (h.sample_count < 2)
    return FailByte(name, offsetof(TraceBinaryHeader, sample_count), "a trace needs at least 2 samples");
  std::uint32_t crc = blob::Crc32c(bytes.first(offsetof(TraceBinaryHeader, crc32c)));
  crc = blob::Crc32c(bytes.subspan(kBinaryHeaderSize), crc);
  if (crc != h.crc32c) return FailByte(name, offsetof(TraceBinaryHeader, crc32c), "checksum mismatch (CRC-32C)");
  constexpr std::int64_t kTimeLimitNs = std::int64_t{1} << 53;  // times stay exact as doubles
  if (h.t0_ns < -kTimeLimitNs || h.t0_ns > kTimeLimitNs)
    return FailByte(name, offsetof(TraceBinaryHeader, t0_ns), "start time out of range");

  TraceFile file;
  file.info.version = 2;
  file.info.binary = true;
  file.info.has_buttons = buttons;
  const std::size_t comment_at = kBinaryHeaderSize;
  file.info.comment.assign(reinterpret_cast<const char*>(bytes.data() + comment_at), h.comment_bytes);
  file.samples.reserve(static_cast<std::size_t>(h.sample_count));
  std::int64_t t_ns = h.t0_ns;
  std::size_t at = comment_at + h.comment_bytes;
  for (std::uint64_t i = 0; i < h.sample_count; ++i, at += record) {
    const auto dt = Load<std::uint32_t>(bytes, at);
    if (i == 0 && dt != 0) return FailByte(name, at, "sample 0: dt must be 0 (the start time is in the header)");
    if (i > 0 && dt == 0) return FailByte(name, at, "sample " + std::to_string(i) + ": time does not increase (dt 0)");
    t_ns += dt;
    if (t_ns > kTimeLimitNs) return FailByte(name, at, "sample " + std::to_string(i) + ": time out of range");
    TraceSample s;
    s.t_s = static_cast<double>(t_ns) / 1e9;
    for (std::size_t k = 0; k < 3; ++k)
      s.hip_m[k] = static_cast<double>(Load<std::int32_t>(bytes, at + 4 + 4 * k)) / 1e9;
    if (buttons) s.buttons = Load<std::uint8_t>(bytes, at + kRecordSize);
    if (!kFalconWorkspace.Contains(s.hip_m))
      return FailByte(name, at + 4, "sample " + std::to_string(i) + ": " + OutsideMessage(s.hip_m));
    file.samples.push_back(s);
  }
  return file;
}

template <typename T>
void Store(std::string& out, std::size_t offset, T v) {
  std::memcpy(out.data() + offset, &v, sizeof v);
}

}  // namespace

std::expected<void, TraceError> CheckSamples(const std::vector<TraceSample>& samples) {
  if (samples.size() < 2)
    return std::unexpected(
        TraceError{0, 0, "a trace needs at least 2 samples, found " + std::to_string(samples.size())});
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const std::string problem = SampleProblem(samples[i], i == 0 ? nullptr : &samples[i - 1]);
    if (!problem.empty()) return std::unexpected(TraceError{0, 0, "sample " + std::to_string(i) + ": " + problem});
  }
  return {};
}

std::expected<TraceFile, TraceError> ParseTraceBytes(std::span<const std::byte> bytes, const std::string& name) {
  if (bytes.size() >= kBinaryMagic.size() && std::memcmp(bytes.data(), kBinaryMagic.data(), kBinaryMagic.size()) == 0)
    return ParseBinary(bytes, name);
  return ParseText(std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()), name);
}

std::expected<std::vector<TraceSample>, TraceError> ParseTrace(const std::string& text, const std::string& name) {
  auto file = ParseText(text, name);
  if (!file) return std::unexpected(std::move(file.error()));
  return std::move(file->samples);
}

std::expected<TraceFile, TraceError> ReadTraceFile(const std::string& path) {
  // A regular file within kMaxTraceFileBytes (a FIFO or /dev/zero is refused before any read).
  auto bytes = io::ReadBounded(path, kMaxTraceFileBytes, "trace file");
  if (!bytes) return std::unexpected(TraceError{0, 0, std::move(bytes.error().message)});
  return ParseTraceBytes(*bytes, io::Escape(path, 256));
}

std::expected<std::vector<TraceSample>, TraceError> ReadTrace(const std::string& path) {
  auto file = ReadTraceFile(path);
  if (!file) return std::unexpected(std::move(file.error()));
  return std::move(file->samples);
}

std::string FormatTrace(const std::vector<TraceSample>& samples, const std::string& comment, bool buttons) {
  for (const auto& s : samples) buttons = buttons || s.buttons != 0;
  std::string out = "# palpa-trace v2 units=s,m frame=device columns=";
  out += buttons ? kColumns5 : kColumns4;
  out += '\n';
  std::size_t pos = 0;
  while (pos < comment.size()) {
    std::size_t end = comment.find('\n', pos);
    if (end == std::string::npos) end = comment.size();
    out += "# ";
    out.append(comment, pos, end - pos);
    out += '\n';
    pos = end + 1;
  }
  out.reserve(out.size() + samples.size() * 56);
  for (const auto& s : samples) {
    AppendNano(out, ToNano(s.t_s));
    for (const double x : s.hip_m) {
      out += ',';
      AppendNano(out, ToNano(x));
    }
    if (buttons) {
      out += ',';
      out += std::to_string(s.buttons);
    }
    out += '\n';
  }
  return out;
}

std::expected<std::string, TraceError> EncodeBinaryTrace(const std::vector<TraceSample>& samples,
                                                         const std::string& comment, bool buttons) {
  if (auto ok = CheckSamples(samples); !ok) return std::unexpected(std::move(ok.error()));
  if (comment.size() > kMaxCommentBytes) return std::unexpected(TraceError{0, 0, "comment longer than 65536 bytes"});
  if (std::fabs(samples.front().t_s) > 9.0e6)  // ±2^53 ns with margin: times stay exact
    return std::unexpected(TraceError{0, 0, "sample 0: start time out of range for the binary form"});
  for (const auto& s : samples) buttons = buttons || s.buttons != 0;
  const std::size_t record = kRecordSize + (buttons ? 1u : 0u);
  std::string out(kBinaryHeaderSize + comment.size() + samples.size() * record, '\0');

  TraceBinaryHeader h{};
  h.magic = kBinaryMagic;
  h.version = kVersion;
  h.flags = buttons ? kFlagButtons : 0;
  h.header_size = kBinaryHeaderSize;
  h.record_size = static_cast<std::uint16_t>(record);
  h.sample_count = samples.size();
  h.t0_ns = ToNano(samples.front().t_s);
  h.comment_bytes = static_cast<std::uint32_t>(comment.size());
  h.payload_size = out.size() - kBinaryHeaderSize;
  std::memcpy(out.data() + kBinaryHeaderSize, comment.data(), comment.size());

  std::size_t at = kBinaryHeaderSize + comment.size();
  std::int64_t previous_ns = h.t0_ns;
  for (std::size_t i = 0; i < samples.size(); ++i, at += record) {
    const std::int64_t t_ns = ToNano(samples[i].t_s);
    const std::int64_t dt = t_ns - previous_ns;
    if (i > 0 && dt <= 0)
      return std::unexpected(TraceError{0, 0, "sample " + std::to_string(i) + ": less than 1 ns after the previous"});
    if (dt > std::numeric_limits<std::uint32_t>::max())
      return std::unexpected(
          TraceError{0, 0, "sample " + std::to_string(i) + ": gap over 4.29 s does not fit the binary form"});
    Store(out, at, static_cast<std::uint32_t>(dt));
    for (std::size_t k = 0; k < 3; ++k)  // inside the workspace: |nm| ≤ 6e7 fits int32
      Store(out, at + 4 + 4 * k, static_cast<std::int32_t>(ToNano(samples[i].hip_m[k])));
    if (buttons) Store(out, at + kRecordSize, samples[i].buttons);
    previous_ns = t_ns;
  }
  std::memcpy(out.data(), &h, sizeof h);
  const auto bytes = std::as_bytes(std::span(out.data(), out.size()));
  std::uint32_t crc = blob::Crc32c(bytes.first(offsetof(TraceBinaryHeader, crc32c)));
  crc = blob::Crc32c(bytes.subspan(kBinaryHeaderSize), crc);
  Store(out, offsetof(TraceBinaryHeader, crc32c), crc);
  return out;
}

TraceStreamWriter::TraceStreamWriter(std::FILE* file, bool binary, std::string comment)
    : file_(file), binary_(binary), comment_(std::move(comment)) {
  if (comment_.size() > kMaxCommentBytes) comment_.resize(kMaxCommentBytes);
}

bool TraceStreamWriter::Begin() {
  std::string head;
  if (binary_) {
    head.assign(kBinaryHeaderSize, '\0');  // rewritten by Finish
    head += comment_;
  } else {
    head = FormatTrace({}, comment_, true);
  }
  io_error_ = std::fwrite(head.data(), 1, head.size(), file_) != head.size();
  return !io_error_;
}

bool TraceStreamWriter::Add(const TraceSample& s) {
  if (io_error_) return false;
  const bool first = written_ == 0;
  const std::int64_t t_ns = std::isfinite(s.t_s) && std::fabs(s.t_s) < 9.0e6 ? ToNano(s.t_s) : 0;
  bool ok = std::isfinite(s.t_s) && std::fabs(s.t_s) < 9.0e6 && kFalconWorkspace.Contains(s.hip_m) &&
            (first || t_ns > last_ns_);
  if (ok && binary_ && !first && t_ns - last_ns_ > std::int64_t{std::numeric_limits<std::uint32_t>::max()}) ok = false;
  if (!ok) {
    ++refused_;
    return false;
  }
  if (binary_) {
    char rec[kRecordSize + 1];
    const auto dt = static_cast<std::uint32_t>(first ? 0 : t_ns - last_ns_);
    std::memcpy(rec, &dt, 4);
    for (std::size_t k = 0; k < 3; ++k) {
      const auto nm = static_cast<std::int32_t>(ToNano(s.hip_m[k]));
      std::memcpy(rec + 4 + 4 * k, &nm, 4);
    }
    rec[kRecordSize] = static_cast<char>(s.buttons);
    io_error_ = std::fwrite(rec, 1, sizeof rec, file_) != sizeof rec;
  } else {
    std::string line;
    AppendNano(line, t_ns);
    for (const double x : s.hip_m) {
      line += ',';
      AppendNano(line, ToNano(x));
    }
    line += ',' + std::to_string(s.buttons) + '\n';
    io_error_ = std::fwrite(line.data(), 1, line.size(), file_) != line.size();
  }
  if (io_error_) return false;
  if (first) t0_ns_ = t_ns;
  last_ns_ = t_ns;
  ++written_;
  return true;
}

std::expected<void, std::string> TraceStreamWriter::Finish() {
  if (io_error_ || std::fflush(file_) != 0) return std::unexpected("write error");
  if (written_ < 2) return std::unexpected("fewer than 2 samples recorded: the trace would not read");
  if (!binary_) return {};
  TraceBinaryHeader h{};
  h.magic = kBinaryMagic;
  h.version = kVersion;
  h.flags = kFlagButtons;
  h.header_size = kBinaryHeaderSize;
  h.record_size = kRecordSize + 1;
  h.sample_count = written_;
  h.t0_ns = t0_ns_;
  h.comment_bytes = static_cast<std::uint32_t>(comment_.size());
  h.payload_size = comment_.size() + written_ * (kRecordSize + 1u);
  // CRC over header bytes [0, 60) then the payload, read back from the file.
  std::uint32_t crc = blob::Crc32c(std::as_bytes(std::span(&h, 1)).first(offsetof(TraceBinaryHeader, crc32c)));
  if (std::fseek(file_, kBinaryHeaderSize, SEEK_SET) != 0) return std::unexpected("cannot seek (not a file?)");
  char buf[65536];
  for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, file_)) > 0;)
    crc = blob::Crc32c(std::as_bytes(std::span(buf, n)), crc);
  if (std::ferror(file_) != 0) return std::unexpected("cannot read the recording back for its checksum");
  h.crc32c = crc;
  if (std::fseek(file_, 0, SEEK_SET) != 0 || std::fwrite(&h, 1, sizeof h, file_) != sizeof h || std::fflush(file_) != 0)
    return std::unexpected("cannot write the header");
  return {};
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
