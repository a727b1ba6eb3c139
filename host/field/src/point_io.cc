#include "palpa/field/point_io.h"

#include "ply.h"

#include <unistd.h>

#include <fmt/format.h>

#include <array>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include "palpa/io/escape.h"
#include "palpa/io/file_safety.h"

namespace palpa::field {
namespace {

constexpr int kNumbersPerLine = 6;
constexpr int kBareNumbersPerLine = 3;  // x y z, ReadOptions::allow_missing_normals
constexpr std::size_t kMinPoints = 4;

bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Parses one token as a double. std::from_chars rejects a leading '+', which some writers emit.
bool ParseNumber(std::string_view token, double& value) {
  if (token.size() > 1 && token.front() == '+') token.remove_prefix(1);
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, value);
  return ec == std::errc() && ptr == end;
}

// The longest .xyz line read: six doubles need at most ~150 bytes; room for comments.
constexpr std::size_t kMaxLineBytes = 4096;
// PLY: the header must end within this many bytes, and the whole file may be at most this large
// (it is read into memory; 1 GiB is 44 million float vertices with normals).
constexpr std::size_t kMaxPlyHeaderBytes = detail::kMaxPlyHeaderBytes;
constexpr std::uint64_t kMaxPlyBytes = std::uint64_t{1} << 30;

std::string Quoted(const std::string& name) { return io::Escape(name, 256); }

std::expected<PointSet, Error> AtLeastFour(const std::string& name, PointSet points) {
  if (points.positions.size() < kMinPoints) {
    return std::unexpected(
        Error{fmt::format("{}: {} points; at least {} are needed", Quoted(name), points.positions.size(), kMinPoints)});
  }
  return points;
}

// AddOrientedPoint, except that a bad normal is kept as (0, 0, 0) (ReadOptions::keep_bad_normals).
std::optional<std::string> AddPointKeepingBadNormal(PointSet& points, const Eigen::Vector3d& p,
                                                    const Eigen::Vector3d& n) {
  if (!p.allFinite()) return "position is not finite";
  if (n.allFinite() && n.cwiseAbs().maxCoeff() > 0.0) return detail::AddOrientedPoint(points, p, n);
  points.positions.push_back(p);
  points.normals.push_back(Eigen::Vector3d::Zero());
  return std::nullopt;
}

// A PLY file: the header is looked for in the first kMaxPlyHeaderBytes (so a file without one is
// refused after reading that much), then the whole file is read within kMaxPlyBytes.
std::expected<PointSet, Error> ReadPlyFile(const std::string& name, const detail::AddPoint& add,
                                           bool allow_missing_normals) {
  std::uint64_t size = 0;
  auto fd = io::OpenRegular(name, "point file", &size);
  if (!fd) return std::unexpected(Error{std::move(fd.error().message)});
  if (size > kMaxPlyBytes) {
    ::close(*fd);
    return std::unexpected(Error{fmt::format("{}: the PLY file holds {} bytes; at most {} are read", Quoted(name), size,
                                             io::FormatBytes(kMaxPlyBytes))});
  }
  std::string text(static_cast<std::size_t>(std::min<std::uint64_t>(size, kMaxPlyHeaderBytes)), '\0');
  std::size_t got = 0;
  bool failed = false;
  int read_errno = 0;
  const auto read_to = [&](std::size_t want) {
    text.resize(want);
    while (got < want) {
      const ssize_t n = ::read(*fd, text.data() + got, want - got);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        failed = n < 0;
        read_errno = errno;
        break;
      }
      got += static_cast<std::size_t>(n);
    }
    text.resize(got);
  };
  read_to(text.size());
  const bool header_ends = text.starts_with("ply") && (text.find("\nend_header") != std::string::npos);
  if (header_ends && !failed) read_to(static_cast<std::size_t>(size));  // else: ReadPly names the header's fault
  ::close(*fd);
  if (failed) return std::unexpected(Error{fmt::format("{}: read error: {}", Quoted(name), std::strerror(read_errno))});
  PointSet points;
  if (auto error = detail::ReadPly(Quoted(name), text, add, points, allow_missing_normals))
    return std::unexpected(Error{std::move(*error)});
  return AtLeastFour(name, std::move(points));
}

}  // namespace

std::string PointPlace(const std::string& file, const PointSet& points, std::size_t index) {
  if (index < points.lines.size()) return fmt::format("{}:{}", file, points.lines[index]);
  return fmt::format("{}: vertex {}", file, index);
}

std::expected<PointSet, Error> ReadPoints(const std::filesystem::path& path, const ReadOptions& options) {
  const std::string name = path.string();
  const std::string ext = Lower(path.extension().string());
  if (ext != ".xyz" && ext != ".pwn" && ext != ".ply") {
    return std::unexpected(Error{fmt::format("{}: unknown extension '{}' (expected .xyz, .pwn or .ply)", Quoted(name),
                                             io::Escape(path.extension().string()))});
  }
  const detail::AddPoint add = options.keep_bad_normals ? AddPointKeepingBadNormal : detail::AddOrientedPoint;
  if (ext == ".ply") return ReadPlyFile(name, add, options.allow_missing_normals);

  // Streamed line by line: memory is bounded by the points, not by what the file holds.
  auto reader = io::LineReader::Open(name, kMaxLineBytes, "point file");
  if (!reader) return std::unexpected(Error{std::move(reader.error().message)});
  PointSet points;
  while (true) {
    std::string_view line;
    const io::LineReader::Status status = reader->Next(line);
    if (status == io::LineReader::Status::kEnd) break;
    const std::uint64_t line_number = reader->line_number();
    if (status == io::LineReader::Status::kTooLong) {
      return std::unexpected(
          Error{fmt::format("{}:{}: the line is longer than {} bytes (a point is one line of six "
                            "numbers)",
                            Quoted(name), line_number, kMaxLineBytes)});
    }
    if (status == io::LineReader::Status::kError) {
      return std::unexpected(Error{fmt::format("{}: read error: {}", Quoted(name), std::strerror(reader->error()))});
    }
    if (const std::size_t hash = line.find('#'); hash != std::string_view::npos) {
      line = line.substr(0, hash);
    }

    std::array<double, kNumbersPerLine> values{};
    int count = 0;
    std::size_t pos = 0;
    while (true) {
      while (pos < line.size() && IsSpace(line[pos])) ++pos;
      if (pos == line.size()) break;
      std::size_t end = pos;
      while (end < line.size() && !IsSpace(line[end])) ++end;
      const std::string_view token = line.substr(pos, end - pos);
      double value = 0.0;
      if (!ParseNumber(token, value)) {
        return std::unexpected(
            Error{fmt::format("{}:{}: '{}' is not a number", Quoted(name), line_number, io::Escape(token))});
      }
      if (count < kNumbersPerLine) values[static_cast<std::size_t>(count)] = value;
      ++count;
      pos = end;
    }
    if (count == 0) continue;  // blank or comment-only line
    // The first point decides whether the file has normals (bare positions only when allowed).
    if (points.positions.empty() && options.allow_missing_normals && count == kBareNumbersPerLine)
      points.has_normals = false;
    const int want = points.has_normals ? kNumbersPerLine : kBareNumbersPerLine;
    if (count != want) {
      return std::unexpected(
          Error{fmt::format("{}:{}: expected {} numbers, found {}{}", Quoted(name), line_number, want, count,
                            points.has_normals ? "" : " (the file's first point has no normal)")});
    }
    const Eigen::Vector3d p(values[0], values[1], values[2]);
    if (!points.has_normals) {
      if (!p.allFinite())
        return std::unexpected(Error{fmt::format("{}:{}: position is not finite", Quoted(name), line_number)});
      points.positions.push_back(p);
      points.normals.push_back(Eigen::Vector3d::Zero());
      points.lines.push_back(static_cast<std::size_t>(line_number));
      continue;
    }
    const Eigen::Vector3d n(values[3], values[4], values[5]);
    if (auto bad = add(points, p, n)) {
      return std::unexpected(Error{fmt::format("{}:{}: {}", Quoted(name), line_number, *bad)});
    }
    if (options.keep_bad_normals) points.lines.push_back(static_cast<std::size_t>(line_number));
  }
  return AtLeastFour(name, std::move(points));
}

}  // namespace palpa::field
