// PLY point sets (Greg Turk's polygon file format, as written by Meshlab, CloudCompare, Open3D and
// PCL): ascii, binary_little_endian and binary_big_endian 1.0. Only the vertex element's x, y, z,
// nx, ny, nz are used; every other property and element is skipped (lists included), so a scanned
// cloud with colours, or a mesh with faces, reads as its oriented vertices.
//
// Not CGAL's reader (libcgal-dev, already used by host/mesh): it reports a bad file on std::cerr
// with no byte offset, and a truncated binary body as a plain failure; this one names the line
// (header, ascii) or the byte (binary) like the .xyz reader, and loses nothing on an error.
#include "ply.h"

#include <fmt/format.h>

#include "palpa/io/escape.h"

#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <optional>
#include <string>
#include <vector>

namespace palpa::field::detail {
namespace {

enum class Format { kAscii, kLittle, kBig };
enum class Type { kI8, kU8, kI16, kU16, kI32, kU32, kF32, kF64 };

struct Property {
  std::string name;
  Type type = Type::kF32;
  bool list = false;
  Type count_type = Type::kU8;  // lists only
};

struct Element {
  std::string name;
  std::uint64_t count = 0;
  std::vector<Property> properties;
};

std::optional<Type> ParseType(std::string_view t) {
  // The spec's names and the sized aliases newer writers use.
  static constexpr std::array<std::pair<std::string_view, Type>, 16> kNames = {{
      {"char", Type::kI8},
      {"int8", Type::kI8},
      {"uchar", Type::kU8},
      {"uint8", Type::kU8},
      {"short", Type::kI16},
      {"int16", Type::kI16},
      {"ushort", Type::kU16},
      {"uint16", Type::kU16},
      {"int", Type::kI32},
      {"int32", Type::kI32},
      {"uint", Type::kU32},
      {"uint32", Type::kU32},
      {"float", Type::kF32},
      {"float32", Type::kF32},
      {"double", Type::kF64},
      {"float64", Type::kF64},
  }};
  for (const auto& [name, type] : kNames) {
    if (t == name) return type;
  }
  return std::nullopt;
}

std::size_t Size(Type t) {
  switch (t) {
    case Type::kI8:
    case Type::kU8:
      return 1;
    case Type::kI16:
    case Type::kU16:
      return 2;
    case Type::kI32:
    case Type::kU32:
    case Type::kF32:
      return 4;
    case Type::kF64:
      return 8;
  }
  return 8;
}

bool IsInteger(Type t) { return t != Type::kF32 && t != Type::kF64; }

std::vector<std::string_view> Words(std::string_view line) {
  std::vector<std::string_view> words;
  std::size_t pos = 0;
  while (true) {
    while (pos < line.size() && (line[pos] == ' ' || line[pos] == '\t' || line[pos] == '\r')) ++pos;
    if (pos == line.size()) break;
    std::size_t end = pos;
    while (end < line.size() && line[end] != ' ' && line[end] != '\t' && line[end] != '\r') ++end;
    words.push_back(line.substr(pos, end - pos));
    pos = end;
  }
  return words;
}

template <typename T>
double As(const std::array<unsigned char, 8>& b) {
  T v;
  std::memcpy(&v, b.data(), sizeof(T));
  return static_cast<double>(v);
}

// A binary value at `p` (the caller checked the bytes are there), as a double.
double Decode(const unsigned char* p, Type t, bool big) {
  std::array<unsigned char, 8> b{};
  const std::size_t n = Size(t);
  for (std::size_t i = 0; i < n; ++i) b[i] = p[big == (std::endian::native == std::endian::little) ? n - 1 - i : i];
  switch (t) {
    case Type::kI8:
      return As<std::int8_t>(b);
    case Type::kU8:
      return As<std::uint8_t>(b);
    case Type::kI16:
      return As<std::int16_t>(b);
    case Type::kU16:
      return As<std::uint16_t>(b);
    case Type::kI32:
      return As<std::int32_t>(b);
    case Type::kU32:
      return As<std::uint32_t>(b);
    case Type::kF32:
      return As<float>(b);
    case Type::kF64:
      return As<double>(b);
  }
  return 0;
}

// The body's values, one at a time: ascii tokens (one element per line, tracking lines) or binary
// values (tracking the byte offset). Next* return false with `error` set.
class Body {
 public:
  Body(std::string_view name, std::string_view text, std::size_t offset, std::size_t line, Format format)
      : name_(name), text_(text), pos_(offset), line_(line), format_(format) {}

  // The place of the value about to be read, for messages: "FILE:LINE" or "FILE: byte N".
  std::string Where() const {
    return format_ == Format::kAscii ? fmt::format("{}:{}", name_, line_) : fmt::format("{}: byte {}", name_, pos_);
  }

  // Ascii: moves to the next non-blank line, where an element's values start.
  void BeginLine() {
    if (format_ != Format::kAscii) return;
    while (pos_ < text_.size() && IsBlank(text_[pos_], true)) {
      if (text_[pos_] == '\n') ++line_;
      ++pos_;
    }
    line_start_ = pos_;
    values_read_ = 0;
  }

  // Ascii: the element's values must end its line. False (with `error`) if more follow.
  bool EndLine(const std::string& what) {
    if (format_ != Format::kAscii) return true;
    SkipInLine();
    if (pos_ == text_.size() || text_[pos_] == '\n') return true;
    error = fmt::format("{}: {} has more values than the header's properties ({} on the line, {} expected)", Where(),
                        what, ValuesOnLine(), values_read_);
    return false;
  }

  bool Next(Type t, const char* what, double& value) {
    if (format_ != Format::kAscii) {
      if (text_.size() - pos_ < Size(t)) {
        error = fmt::format("{}: the file ends inside {} ({} of {} bytes there)", Where(), what, text_.size() - pos_,
                            Size(t));
        return false;
      }
      value = Decode(reinterpret_cast<const unsigned char*>(text_.data()) + pos_, t, format_ == Format::kBig);
      pos_ += Size(t);
      return true;
    }
    SkipInLine();
    if (pos_ == text_.size() && line_start_ == text_.size()) {
      error = fmt::format("{}: the file ends before {}", Where(), what);
      return false;
    }
    if (pos_ == text_.size() || text_[pos_] == '\n') {
      error = fmt::format("{}: the line ends before {} ({} values on the line, more expected)", Where(), what,
                          ValuesOnLine());
      return false;
    }
    std::size_t end = pos_;
    while (end < text_.size() && !IsBlank(text_[end], true)) ++end;
    std::string_view token = text_.substr(pos_, end - pos_);
    if (token.size() > 1 && token.front() == '+') token.remove_prefix(1);
    bool ok = false;
    if (IsInteger(t)) {
      std::int64_t integer = 0;
      const auto [ptr, ec] = std::from_chars(token.data(), token.data() + token.size(), integer);
      ok = ec == std::errc() && ptr == token.data() + token.size();
      value = static_cast<double>(integer);
    } else {
      const auto [ptr, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
      ok = ec == std::errc() && ptr == token.data() + token.size();
    }
    if (!ok) {
      error = fmt::format("{}: '{}' is not a valid {} for {}", Where(), io::Escape(text_.substr(pos_, end - pos_)),
                          IsInteger(t) ? "integer" : "number", what);
      return false;
    }
    pos_ = end;
    ++values_read_;
    return true;
  }

  std::string error;

 private:
  static bool IsBlank(char c, bool newline) { return c == ' ' || c == '\t' || c == '\r' || (newline && c == '\n'); }
  void SkipInLine() {
    while (pos_ < text_.size() && IsBlank(text_[pos_], false)) ++pos_;
  }
  // Whitespace-separated values on the current line, for messages.
  std::size_t ValuesOnLine() const {
    std::size_t end = text_.find('\n', line_start_);
    if (end == std::string_view::npos) end = text_.size();
    std::size_t count = 0;
    for (std::size_t i = line_start_; i < end; ++i) {
      if (!IsBlank(text_[i], false) && (i == line_start_ || IsBlank(text_[i - 1], false))) ++count;
    }
    return count;
  }

  std::string_view name_;
  std::string_view text_;
  std::size_t pos_;
  std::size_t line_;
  std::size_t line_start_ = 0;
  std::size_t values_read_ = 0;
  Format format_;
};

}  // namespace

// Here rather than in point_io.cc so that the fuzzer (clang 14) builds it with the PLY reader.
std::optional<std::string> AddOrientedPoint(PointSet& points, const Eigen::Vector3d& p, const Eigen::Vector3d& n) {
  if (!p.allFinite()) return "position is not finite";
  if (!n.allFinite()) return "normal is not finite";
  const double largest = n.cwiseAbs().maxCoeff();
  if (!(largest > 0.0)) return "normal has zero length";
  // n / |n| unless |n|² leaves the normal doubles (components below ~1e-154, where the squares
  // lose bits, or above ~1e154, where they overflow): then scale by the largest first. Found by
  // fuzz/ply_fuzz.cc (a PLY normal of 1e-160 per axis came out 1.5e-8 short of unit length).
  const double length = n.norm();
  const bool safe = length > 1e-150 && length < 1e150;
  const Eigen::Vector3d scaled = safe ? n : Eigen::Vector3d(n / largest);
  points.positions.push_back(p);
  points.normals.push_back(safe ? Eigen::Vector3d(n / length) : Eigen::Vector3d(scaled / scaled.norm()));
  return std::nullopt;
}

std::optional<std::string> ReadPly(const std::string& name, std::string_view text, const AddPoint& add,
                                   PointSet& points, bool allow_missing_normals) {
  const auto fail = [](std::string message) { return std::optional<std::string>(std::move(message)); };
  // Header: lines up to "end_header".
  std::size_t pos = 0, line_number = 0;
  std::optional<Format> format;
  std::vector<Element> elements;
  bool ended = false;
  while (pos < text.size() && !ended) {
    ++line_number;
    const std::size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos || eol >= kMaxPlyHeaderBytes) break;
    const std::string_view line = text.substr(pos, eol - pos);
    pos = eol + 1;
    const std::vector<std::string_view> w = Words(line);
    const auto here = fmt::format("{}:{}", name, line_number);
    if (line_number == 1) {
      if (w.size() != 1 || w[0] != "ply")
        return fail(fmt::format("{}: not a PLY file (the first line is not 'ply')", here));
      continue;
    }
    if (w.empty() || w[0] == "comment" || w[0] == "obj_info") continue;
    if (w[0] == "format") {
      if (w.size() != 3 || w[2] != "1.0") return fail(fmt::format("{}: expected 'format <type> 1.0'", here));
      if (w[1] == "ascii") {
        format = Format::kAscii;
      } else if (w[1] == "binary_little_endian") {
        format = Format::kLittle;
      } else if (w[1] == "binary_big_endian") {
        format = Format::kBig;
      } else {
        return fail(fmt::format("{}: unknown format '{}' (ascii, binary_little_endian or binary_big_endian)", here,
                                io::Escape(w[1])));
      }
    } else if (w[0] == "element") {
      std::uint64_t count = 0;
      if (w.size() != 3) return fail(fmt::format("{}: expected 'element <name> <count>'", here));
      const auto [end, ec] = std::from_chars(w[2].data(), w[2].data() + w[2].size(), count);
      if (ec == std::errc::result_out_of_range)
        return fail(fmt::format("{}: element count '{}' is not below 2^64", here, io::Escape(w[2])));
      if (ec != std::errc() || end != w[2].data() + w[2].size())
        return fail(fmt::format("{}: element count '{}' is not a count", here, io::Escape(w[2])));
      elements.push_back({std::string(w[1]), count, {}});
    } else if (w[0] == "property") {
      if (elements.empty()) return fail(fmt::format("{}: a property before any element", here));
      Property p;
      if (w.size() == 5 && w[1] == "list") {
        const auto count_type = ParseType(w[2]), item_type = ParseType(w[3]);
        if (!count_type || !item_type || !IsInteger(*count_type)) {
          return fail(fmt::format("{}: bad list property types '{} {}'", here, io::Escape(w[2]), io::Escape(w[3])));
        }
        p = {std::string(w[4]), *item_type, true, *count_type};
      } else if (w.size() == 3) {
        const auto type = ParseType(w[1]);
        if (!type) return fail(fmt::format("{}: unknown property type '{}'", here, io::Escape(w[1])));
        p = {std::string(w[2]), *type, false, Type::kU8};
      } else {
        return fail(fmt::format("{}: expected 'property <type> <name>' or 'property list <type> <type> <name>'", here));
      }
      elements.back().properties.push_back(p);
    } else if (w[0] == "end_header") {
      ended = true;
    } else {
      return fail(fmt::format("{}: unknown header keyword '{}'", here, io::Escape(w[0])));
    }
  }
  if (!ended && pos < text.size() && text.size() >= kMaxPlyHeaderBytes)
    return fail(
        fmt::format("{}: the header has no 'end_header' line in its first {} KiB", name, kMaxPlyHeaderBytes / 1024));
  if (!ended) return fail(fmt::format("{}: the header has no 'end_header' line", name));
  if (!format) return fail(fmt::format("{}: the header has no 'format' line", name));

  // The vertex element and where x … nz are among its properties.
  std::size_t vertex = elements.size();
  for (std::size_t e = 0; e < elements.size(); ++e) {
    if (elements[e].name == "vertex") vertex = e;
  }
  if (vertex == elements.size()) return fail(fmt::format("{}: the header declares no 'vertex' element", name));
  static constexpr std::array<const char*, 6> kWanted = {"x", "y", "z", "nx", "ny", "nz"};
  // PCL writes its normals as normal_x … normal_z.
  static constexpr std::array<const char*, 6> kAlias = {"x", "y", "z", "normal_x", "normal_y", "normal_z"};
  std::array<std::size_t, 6> slot{};
  std::string missing;
  for (std::size_t k = 0; k < kWanted.size(); ++k) {
    slot[k] = elements[vertex].properties.size();
    for (std::size_t i = 0; i < elements[vertex].properties.size(); ++i) {
      const Property& p = elements[vertex].properties[i];
      if ((p.name == kWanted[k] || p.name == kAlias[k]) && !p.list) slot[k] = i;
    }
    if (slot[k] == elements[vertex].properties.size())
      missing += fmt::format("{}{}", missing.empty() ? "" : ", ", kWanted[k]);
  }
  // Bare positions: allowed only when the caller estimates the normals, and only when all three
  // normal properties are absent (one or two of them is a broken file, not a scanner's output).
  const bool bare = allow_missing_normals && slot[0] < elements[vertex].properties.size() &&
                    slot[1] < elements[vertex].properties.size() && slot[2] < elements[vertex].properties.size() &&
                    missing == "nx, ny, nz";
  if (!missing.empty() && !bare) {
    return fail(fmt::format("{}: the vertex element has no scalar {} (oriented points need x y z nx ny nz{})", name,
                            missing, allow_missing_normals ? "; bare positions need x y z" : ""));
  }
  if (bare) points.has_normals = false;

  // Body: elements in header order; those before the vertices are read and dropped, those after
  // are not needed.
  // A count far beyond what the rest of the file can hold (an ascii element takes at least two bytes
  // per property, a digit and a separator; a binary one its scalar sizes) is refused before any
  // value is read; a file merely cut short is reported where it ends, below.
  std::uint64_t body_bytes = text.size() - pos;
  for (std::size_t e = 0; e <= vertex; ++e) {
    const Element& element = elements[e];
    std::uint64_t least = 0;
    for (const Property& p : element.properties)
      least += *format == Format::kAscii ? 2 : Size(p.list ? p.count_type : p.type);
    if (least == 0) continue;
    const std::uint64_t room = (body_bytes + 1) / least;
    if (element.count / 2 > room) {
      return fail(fmt::format("{}: the header declares {} '{}' elements, but the {} bytes after it hold at most {}",
                              name, element.count, io::Escape(element.name), body_bytes, room));
    }
    body_bytes -= std::min(body_bytes, element.count * least);
  }

  Body body(name, text, pos, line_number + 1, *format);
  for (std::size_t e = 0; e <= vertex; ++e) {
    const Element& element = elements[e];
    if (element.properties.empty()) continue;  // takes no bytes, whatever its count
    std::vector<double> values(element.properties.size());
    for (std::uint64_t n = 0; n < element.count; ++n) {
      body.BeginLine();
      const std::string where = body.Where();
      const std::string which = fmt::format("{} {} of {}", io::Escape(element.name), n, element.count);
      for (std::size_t i = 0; i < element.properties.size(); ++i) {
        const Property& p = element.properties[i];
        const std::string what = fmt::format("{} '{}'", which, io::Escape(p.name));
        if (!p.list) {
          if (!body.Next(p.type, what.c_str(), values[i])) return fail(body.error);
          continue;
        }
        double count = 0;
        if (!body.Next(p.count_type, what.c_str(), count)) return fail(body.error);
        if (count < 0) return fail(fmt::format("{}: negative list length {} in {}", body.Where(), count, what));
        for (double item = 0, k = 0; k < count; ++k) {
          if (!body.Next(p.type, what.c_str(), item)) return fail(body.error);
        }
      }
      if (!body.EndLine(which)) return fail(body.error);
      if (e != vertex) continue;
      const Eigen::Vector3d position(values[slot[0]], values[slot[1]], values[slot[2]]);
      if (bare) {
        if (!position.allFinite()) return fail(fmt::format("{} (vertex {}): position is not finite", where, n));
        points.positions.push_back(position);
        points.normals.push_back(Eigen::Vector3d::Zero());
        continue;
      }
      const Eigen::Vector3d normal(values[slot[3]], values[slot[4]], values[slot[5]]);
      if (auto bad = add(points, position, normal)) {
        return fail(fmt::format("{} (vertex {}): {}", where, n, *bad));
      }
    }
  }
  return std::nullopt;
}

}  // namespace palpa::field::detail
