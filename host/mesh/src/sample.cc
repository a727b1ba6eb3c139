#include "palpa/mesh/sample.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

#include "palpa/mesh/mesh_distance.h"

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

std::expected<field::PointSet, Error> RangeScan(const TriangleMesh& mesh, std::size_t count, int views,
                                                double range_noise, std::uint64_t seed, const std::string& name) {
  if (count == 0) return std::unexpected(Error{name + ": asked for 0 points"});
  if (views < 1) return std::unexpected(Error{name + ": a range scan needs at least 1 view"});
  if (auto ok = CheckClosedOriented(mesh, name); !ok) return std::unexpected(ok.error());
  const double outward = SignedVolume(mesh) < 0 ? -1.0 : 1.0;
  Eigen::Vector3d lo = mesh.vertices[0], hi = lo;
  for (const Eigen::Vector3d& v : mesh.vertices) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  double radius = 0;
  for (const Eigen::Vector3d& v : mesh.vertices) radius = std::max(radius, (v - centre).norm());
  const double distance = 2.5 * radius;
  const double half_width = std::tan(std::asin(radius / distance));  // image plane at 1 unit
  const ExactMeshDistance exact(mesh);
  std::mt19937_64 rng(seed);
  const auto gauss = [&] {
    const double u1 = (static_cast<double>(rng() >> 11) + 0.5) * 0x1.0p-53;
    const double u2 = Unit(rng);
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  };
  const auto side =
      static_cast<std::size_t>(std::ceil(std::sqrt(2.0 * static_cast<double>(count) / static_cast<double>(views))));
  const double sin_lo = std::sin(10.0 * std::numbers::pi / 180), sin_hi = std::sin(80.0 * std::numbers::pi / 180);
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  const double grazing = std::cos(80.0 * std::numbers::pi / 180);
  field::PointSet out;
  for (int v = 0; v < views; ++v) {
    const double z = sin_lo + (sin_hi - sin_lo) * (v + 0.5) / views;
    const double rho = std::sqrt(1 - z * z), azimuth = golden * v;
    const Eigen::Vector3d eye_dir(rho * std::cos(azimuth), rho * std::sin(azimuth), z);
    const Eigen::Vector3d eye = centre + distance * eye_dir;
    const Eigen::Vector3d forward = -eye_dir;
    const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
    const Eigen::Vector3d up = right.cross(forward);
    for (std::size_t a = 0; a < side; ++a) {
      for (std::size_t b = 0; b < side; ++b) {
        const double x = half_width * (2.0 * (static_cast<double>(a) + Unit(rng)) / static_cast<double>(side) - 1.0);
        const double y = half_width * (2.0 * (static_cast<double>(b) + Unit(rng)) / static_cast<double>(side) - 1.0);
        const Eigen::Vector3d dir = (forward + x * right + y * up).normalized();
        const double noise = range_noise > 0 ? range_noise * gauss() : 0.0;
        const auto hit = exact.FirstHit(eye, dir);
        if (!hit) continue;
        const Eigen::Vector3d normal = outward * FaceNormal(mesh, hit->face);
        if (-dir.dot(normal) < grazing) continue;  // grazing, or the face's back
        out.positions.push_back(hit->point + noise * dir);
        out.normals.push_back(normal);
      }
    }
  }
  // Keep `count` of the hits, chosen by a seeded Fisher-Yates shuffle, in their scan order.
  if (out.positions.size() > count) {
    std::vector<std::size_t> order(out.positions.size());
    for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
    for (std::size_t i = order.size() - 1; i > 0; --i) std::swap(order[i], order[rng() % (i + 1)]);
    order.resize(count);
    std::sort(order.begin(), order.end());
    field::PointSet kept;
    for (const std::size_t i : order) {
      kept.positions.push_back(out.positions[i]);
      kept.normals.push_back(out.normals[i]);
    }
    out = std::move(kept);
  }
  if (out.positions.empty()) return std::unexpected(Error{name + ": no ray of the range scan hit the mesh"});
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
