#include "palpa/mesh/sample.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <fmt/core.h>

namespace palpa::mesh {
namespace {

// Uniform double in [0, 1) from the top 53 bits: exact and portable, unlike
// std::uniform_real_distribution whose algorithm is implementation-defined.
double Unit(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

}  // namespace

std::expected<field::PointSet, Error> SampleSurface(const TriangleMesh& mesh, std::size_t count, std::uint64_t seed,
                                                    const std::string& name) {
  if (count == 0) return std::unexpected(Error{name + ": asked for 0 points"});
  if (auto ok = CheckClosedOriented(mesh, name); !ok) return std::unexpected(ok.error());
  const double outward = SignedVolume(mesh) < 0 ? -1.0 : 1.0;

  std::vector<double> cumulative(mesh.faces.size());
  double total = 0;
  for (std::size_t f = 0; f < mesh.faces.size(); ++f) {
    const auto& t = mesh.faces[f];
    const Eigen::Vector3d& p0 = mesh.vertices[static_cast<std::size_t>(t[0])];
    total += 0.5 * (mesh.vertices[static_cast<std::size_t>(t[1])] - p0)
                       .cross(mesh.vertices[static_cast<std::size_t>(t[2])] - p0)
                       .norm();
    cumulative[f] = total;
  }
  if (!(total > 0)) return std::unexpected(Error{name + ": the mesh has zero surface area"});

  std::mt19937_64 rng(seed);
  field::PointSet out;
  out.positions.reserve(count);
  out.normals.reserve(count);
  for (std::size_t s = 0; s < count; ++s) {
    // upper_bound skips zero-area faces: their cumulative value equals the previous one.
    const double u = Unit(rng) * total;
    auto it = std::upper_bound(cumulative.begin(), cumulative.end(), u);
    if (it == cumulative.end()) --it;  // u == total after rounding
    const auto f = static_cast<std::size_t>(it - cumulative.begin());
    const auto& t = mesh.faces[f];
    const double r1 = std::sqrt(Unit(rng));
    const double r2 = Unit(rng);
    out.positions.push_back((1 - r1) * mesh.vertices[static_cast<std::size_t>(t[0])] +
                            r1 * (1 - r2) * mesh.vertices[static_cast<std::size_t>(t[1])] +
                            r1 * r2 * mesh.vertices[static_cast<std::size_t>(t[2])]);
    out.normals.push_back(outward * FaceNormal(mesh, f));
  }
  return out;
}

std::string ToXyzText(const field::PointSet& points) {
  std::string text;
  text.reserve(points.positions.size() * 96);
  for (std::size_t i = 0; i < points.positions.size(); ++i) {
    const Eigen::Vector3d& p = points.positions[i];
    const Eigen::Vector3d& n = points.normals[i];
    fmt::format_to(std::back_inserter(text), "{:.9g} {:.9g} {:.9g} {:.9g} {:.9g} {:.9g}\n", p.x(), p.y(), p.z(), n.x(),
                   n.y(), n.z());
  }
  return text;
}

}  // namespace palpa::mesh
