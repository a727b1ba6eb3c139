#include "palpa/mesh/triangle_mesh.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <string_view>
#include <utility>

#include <fmt/core.h>

#include "palpa/io/escape.h"
#include "palpa/io/file_safety.h"
#include "triangle_mesh_internal.h"

namespace palpa::mesh {
namespace {

// Splits a line into whitespace-separated tokens, dropping a `#` comment.
std::vector<std::string_view> Tokens(std::string_view line) {
  if (const auto hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    const std::size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    if (i > start) out.push_back(line.substr(start, i - start));
  }
  return out;
}

template <typename T>
bool Parse(std::string_view token, T& value) {
  const char* first = token.data();
  const char* last = token.data() + token.size();
  if (first != last && *first == '+') ++first;  // from_chars refuses a leading '+'
  const auto [ptr, ec] = std::from_chars(first, last, value);
  return ec == std::errc() && ptr == last;
}

// Reads the file line by line (bounded: io::LineReader), handing out only lines that hold tokens.
// False at the end, or with error() set for a line too long or a read error.
class LineReader {
 public:
  explicit LineReader(io::LineReader& in) : in_(in) {}
  bool Next(std::vector<std::string_view>& tokens) {
    std::string_view text;
    while (true) {
      const io::LineReader::Status status = in_.Next(text);
      line_ = static_cast<int>(in_.line_number());
      if (status == io::LineReader::Status::kTooLong)
        error_ = fmt::format("the line is longer than {} bytes", kMaxLine);
      if (status == io::LineReader::Status::kError) error_ = fmt::format("read error: {}", std::strerror(in_.error()));
      if (status != io::LineReader::Status::kLine) return false;
      tokens = Tokens(text);
      if (!tokens.empty()) return true;
    }
  }
  int line() const { return line_; }
  const std::string& error() const { return error_; }
  static constexpr std::size_t kMaxLine = 4096;

 private:
  io::LineReader& in_;
  std::string error_;
  int line_ = 0;
};

// Geomview's OFF(5) keyword: `[ST][C][N][4][n]OFF`. ST, C and N add texture coordinates, a colour
// and a normal after each vertex's x y z; 4 (homogeneous) and n (any dimension) change the
// coordinates themselves and are refused. Empty when the keyword is read, else the error.
std::string OffKeywordError(std::string_view keyword) {
  std::string_view k = keyword;
  if (k.size() < 3 || k.substr(k.size() - 3) != "OFF")
    return fmt::format("expected the 'OFF' header, found '{}'", io::Escape(keyword));
  k.remove_suffix(3);
  for (std::string_view prefix : {"ST", "C", "N"})
    if (k.starts_with(prefix)) k.remove_prefix(prefix.size());
  if (k == "4" || k == "n" || k == "4n")
    return fmt::format("'{}' (homogeneous or n-dimensional OFF) is not read; palpa reads 3-D OFF", io::Escape(keyword));
  if (!k.empty()) return fmt::format("expected the 'OFF' header, found '{}'", io::Escape(keyword));
  return {};
}

std::uint64_t EdgeKey(int a, int b) {
  return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(a)) << 32) | static_cast<std::uint32_t>(b);
}

}  // namespace

std::expected<TriangleMesh, Error> ReadOff(const std::filesystem::path& path) {
  const std::string file = io::Escape(path.string(), 256);
  auto in = io::LineReader::Open(path.string(), LineReader::kMaxLine, "mesh file");
  if (!in) return std::unexpected(Error{std::move(in.error().message)});
  LineReader reader(*in);
  auto fail = [&](const std::string& what) {
    return std::unexpected(
        Error{fmt::format("{}:{}: {}", file, reader.line(), reader.error().empty() ? what : reader.error())});
  };

  std::vector<std::string_view> t;
  if (!reader.Next(t)) {
    if (!reader.error().empty()) return fail("");
    return std::unexpected(Error{file + ": empty file, expected an OFF header"});
  }
  // The header is `[ST][C][N]OFF` (Geomview's OFF(5)), optionally followed by the counts on the
  // same line. The prefixes only add numbers after a vertex's x y z, which are ignored.
  if (const std::string error = OffKeywordError(t[0]); !error.empty()) return fail(error);
  t.erase(t.begin());
  if (!t.empty() && t[0] == "BINARY") return fail("binary OFF is not read; write it as ASCII OFF");
  if (t.empty() && !reader.Next(t)) return fail("expected the counts line 'vertices faces edges'");
  if (t.size() < 2 || t.size() > 3) return fail("expected the counts line 'vertices faces edges'");
  long long nv = 0;
  long long nf = 0;
  if (!Parse(t[0], nv) || !Parse(t[1], nf)) return fail("vertex and face counts must be integers");
  if (nv < 4 || nf < 4) return fail(fmt::format("{} vertices and {} faces cannot enclose a volume", nv, nf));
  constexpr long long kMaxCount = 1LL << 28;
  constexpr int kMaxPolygon = 256;
  if (nv > kMaxCount || nf > kMaxCount) return fail("more than 2^28 vertices or faces");

  TriangleMesh mesh;
  // Reserved only as far as the file can hold (a vertex line takes at least 6 bytes, "0 0 0\n"; a
  // face 8): a header's counts alone never allocate gigabytes for a small file.
  const std::uint64_t size = in->size();
  mesh.vertices.reserve(static_cast<std::size_t>(std::min<std::uint64_t>(static_cast<std::uint64_t>(nv), size / 6)));
  for (long long v = 0; v < nv; ++v) {
    if (!reader.Next(t)) return fail(fmt::format("file ends after {} of {} vertices", v, nv));
    if (t.size() < 3) return fail(fmt::format("vertex {} needs 3 coordinates, found {}", v, t.size()));
    Eigen::Vector3d p;
    for (int a = 0; a < 3; ++a) {
      const auto token = t[static_cast<std::size_t>(a)];
      if (!Parse(token, p[a])) return fail(fmt::format("'{}' is not a number", io::Escape(token)));
      if (!std::isfinite(p[a])) return fail(fmt::format("vertex {} has a non-finite coordinate", v));
    }
    mesh.vertices.push_back(p);
  }
  const auto faces = static_cast<std::size_t>(std::min<std::uint64_t>(static_cast<std::uint64_t>(nf), size / 8));
  mesh.faces.reserve(faces);
  mesh.face_lines.reserve(faces);
  std::vector<int> polygon;
  std::vector<Eigen::Vector3d> corners;
  std::vector<std::array<int, 3>> triangles;
  for (long long f = 0; f < nf; ++f) {
    if (!reader.Next(t)) return fail(fmt::format("file ends after {} of {} faces", f, nf));
    int n = 0;
    if (!Parse(t[0], n)) return fail(fmt::format("'{}' is not a vertex count", io::Escape(t[0])));
    if (n < 3) return fail(fmt::format("face {} has {} vertices; a face needs at least 3", f, n));
    // The triangulation of a non-planar polygon is cubic in its size.
    if (n > kMaxPolygon)
      return fail(fmt::format("face {} has {} vertices; palpa reads polygons of up to {}", f, n, kMaxPolygon));
    if (t.size() < static_cast<std::size_t>(n) + 1)
      return fail(fmt::format("face {} lists {} of {} vertex indices", f, t.size() - 1, n));
    polygon.clear();
    for (int a = 0; a < n; ++a) {
      const auto token = t[static_cast<std::size_t>(a + 1)];
      int index = 0;
      if (!Parse(token, index)) return fail(fmt::format("'{}' is not a vertex index", io::Escape(token)));
      if (index < 0 || index >= nv)
        return fail(fmt::format("vertex index {} is out of range [0, {})", io::Escape(token), nv));
      if (std::find(polygon.begin(), polygon.end(), index) != polygon.end())
        return fail(fmt::format("face {} repeats a vertex", f));
      polygon.push_back(index);
    }
    if (n == 3) {
      mesh.faces.push_back({polygon[0], polygon[1], polygon[2]});
      mesh.face_lines.push_back(reader.line());
      continue;
    }
    corners.clear();
    for (const int v : polygon) corners.push_back(mesh.vertices[static_cast<std::size_t>(v)]);
    if (!internal::TriangulatePolygon(corners, triangles))
      return fail(
          fmt::format("face {} is a polygon of {} vertices that has no triangulation (it crosses itself or "
                      "is degenerate)",
                      f, n));
    for (const auto& tri : triangles) {
      mesh.faces.push_back({polygon[static_cast<std::size_t>(tri[0])], polygon[static_cast<std::size_t>(tri[1])],
                            polygon[static_cast<std::size_t>(tri[2])]});
      mesh.face_lines.push_back(reader.line());
    }
  }
  if (reader.Next(t)) return fail("unexpected data after the last face");
  if (!reader.error().empty()) return fail("");
  return mesh;
}

std::expected<void, Error> CheckClosedOriented(const TriangleMesh& mesh, const std::string& name) {
  // Sorted directed edges: each must be unique and have its reverse. Keys alone (8 bytes an edge:
  // palpa mesh checks 21 M edges at 1,200 cells); the faces are found again for a message.
  std::vector<std::uint64_t> edges;
  edges.reserve(3 * mesh.faces.size());
  for (const auto& f : mesh.faces)
    for (std::size_t a = 0; a < 3; ++a) edges.push_back(EdgeKey(f[a], f[(a + 1) % 3]));
  std::sort(edges.begin(), edges.end());
  auto where = [&](std::uint64_t key, std::size_t skip) {
    std::size_t f = 0;
    for (std::size_t seen = 0; f < mesh.faces.size(); ++f) {
      bool has = false;
      for (std::size_t a = 0; a < 3; ++a) has = has || EdgeKey(mesh.faces[f][a], mesh.faces[f][(a + 1) % 3]) == key;
      if (has && seen++ == skip) break;
    }
    return f < mesh.face_lines.size() ? fmt::format("{}:{}: face {}", name, mesh.face_lines[f], f)
                                      : fmt::format("{}: face {}", name, f);
  };
  for (std::size_t e = 0; e < edges.size(); ++e) {
    const auto a = static_cast<int>(edges[e] >> 32);
    const auto b = static_cast<int>(edges[e] & 0xffffffffu);
    if (e + 1 < edges.size() && edges[e + 1] == edges[e]) {
      const std::string second = where(edges[e], 1);
      return std::unexpected(Error{
          fmt::format("{}: edge {}->{} is also used by face {}: the mesh is non-manifold or inconsistently oriented",
                      where(edges[e], 0), a, b, second.substr(second.rfind(' ') + 1))});
    }
    if (!std::binary_search(edges.begin(), edges.end(), EdgeKey(b, a)))
      return std::unexpected(
          Error{fmt::format("{}: edge {}-{} has no opposite face: the mesh must be closed", where(edges[e], 0), a, b)});
  }
  return {};
}

double SignedVolume(const TriangleMesh& mesh) {
  double six_v = 0;
  for (const auto& f : mesh.faces)
    six_v += mesh.vertices[static_cast<std::size_t>(f[0])].dot(
        mesh.vertices[static_cast<std::size_t>(f[1])].cross(mesh.vertices[static_cast<std::size_t>(f[2])]));
  return six_v / 6.0;
}

double SurfaceArea(const TriangleMesh& mesh) {
  double area = 0;
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d& p0 = mesh.vertices[static_cast<std::size_t>(f[0])];
    area += 0.5 * (mesh.vertices[static_cast<std::size_t>(f[1])] - p0)
                      .cross(mesh.vertices[static_cast<std::size_t>(f[2])] - p0)
                      .norm();
  }
  return area;
}

bool OrientOutward(TriangleMesh& mesh) {
  if (SignedVolume(mesh) >= 0) return false;
  for (auto& f : mesh.faces) std::swap(f[1], f[2]);
  for (auto& n : mesh.normals) n = -n;
  return true;
}

std::expected<TriangleMesh, Error> ReadClosedMesh(const std::filesystem::path& path, bool* flipped) {
  auto mesh = ReadOff(path);
  if (!mesh) return mesh;
  if (auto ok = CheckClosedOriented(*mesh, path.string()); !ok) return std::unexpected(ok.error());
  // Relative to the bounding box, so that the test does not depend on the model's units.
  Eigen::Vector3d lo = mesh->vertices[0];
  Eigen::Vector3d hi = lo;
  for (const auto& v : mesh->vertices) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  const double extent = (hi - lo).maxCoeff();
  if (!(std::abs(SignedVolume(*mesh)) > 1e-12 * extent * extent * extent))
    return std::unexpected(Error{path.string() + ": the mesh encloses no volume"});
  const bool f = OrientOutward(*mesh);
  if (flipped != nullptr) *flipped = f;
  return mesh;
}

Eigen::Vector3d FaceNormal(const TriangleMesh& mesh, std::size_t f) {
  const auto& t = mesh.faces[f];
  const Eigen::Vector3d& p0 = mesh.vertices[static_cast<std::size_t>(t[0])];
  const Eigen::Vector3d n =
      (mesh.vertices[static_cast<std::size_t>(t[1])] - p0).cross(mesh.vertices[static_cast<std::size_t>(t[2])] - p0);
  const double len = n.norm();
  return len > 0 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
}

}  // namespace palpa::mesh
