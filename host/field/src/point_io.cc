#include "palpa/field/point_io.h"

#include "ply.h"

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

namespace palpa::field {
namespace {

constexpr int kNumbersPerLine = 6;
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

std::expected<PointSet, Error> AtLeastFour(const std::string& name, PointSet points) {
  if (points.positions.size() < kMinPoints) {
    return std::unexpected(
        Error{fmt::format("{}: {} points; at least {} are needed", name, points.positions.size(), kMinPoints)});
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

}  // namespace

std::string PointPlace(const std::string& file, const PointSet& points, std::size_t index) {
  if (index < points.lines.size()) return fmt::format("{}:{}", file, points.lines[index]);
  return fmt::format("{}: vertex {}", file, index);
}

std::expected<PointSet, Error> ReadPoints(const std::filesystem::path& path, const ReadOptions& options) {
  const std::string name = path.string();
  const std::string ext = Lower(path.extension().string());
  if (ext != ".xyz" && ext != ".pwn" && ext != ".ply") {
    return std::unexpected(Error{
        fmt::format("{}: unknown extension '{}' (expected .xyz, .pwn or .ply)", name, path.extension().string())});
  }
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return std::unexpected(Error{fmt::format("{}: is a directory, not a point file", name)});
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return std::unexpected(Error{fmt::format("{}: cannot open file: {}", name, std::strerror(errno))});
  }
  const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  if (in.bad()) {
    return std::unexpected(Error{fmt::format("{}: read error", name)});
  }
  if (ext == ".ply") {
    PointSet points;
    const detail::AddPoint add = options.keep_bad_normals ? AddPointKeepingBadNormal : detail::AddOrientedPoint;
    if (auto error = detail::ReadPly(name, text, add, points)) return std::unexpected(Error{std::move(*error)});
    return AtLeastFour(name, std::move(points));
  }

  PointSet points;
  std::string_view rest = text;
  std::size_t line_number = 0;
  while (!rest.empty()) {
    ++line_number;
    const std::size_t eol = rest.find('\n');
    std::string_view line = rest.substr(0, eol);
    rest = eol == std::string_view::npos ? std::string_view{} : rest.substr(eol + 1);
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
        return std::unexpected(Error{fmt::format("{}:{}: '{}' is not a number", name, line_number, token)});
      }
      if (count < kNumbersPerLine) values[static_cast<std::size_t>(count)] = value;
      ++count;
      pos = end;
    }
    if (count == 0) continue;  // blank or comment-only line
    if (count != kNumbersPerLine) {
      return std::unexpected(
          Error{fmt::format("{}:{}: expected {} numbers, found {}", name, line_number, kNumbersPerLine, count)});
    }
    const Eigen::Vector3d p(values[0], values[1], values[2]);
    const Eigen::Vector3d n(values[3], values[4], values[5]);
    const detail::AddPoint add = options.keep_bad_normals ? AddPointKeepingBadNormal : detail::AddOrientedPoint;
    if (auto bad = add(points, p, n)) {
      return std::unexpected(Error{fmt::format("{}:{}: {}", name, line_number, *bad)});
    }
    if (options.keep_bad_normals) points.lines.push_back(line_number);
  }
  return AtLeastFour(name, std::move(points));
}

}  // namespace palpa::field
