#include "palpa/mesh/eval.h"

#include "palpa/field/winding.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include <fmt/core.h>

#include "palpa/mesh/field_file.h"
#include "palpa/mesh/mesh_distance.h"

namespace palpa::mesh {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

std::size_t NodeCount(const std::array<int, 3>& d) {
  return static_cast<std::size_t>(d[0]) * static_cast<std::size_t>(d[1]) * static_cast<std::size_t>(d[2]);
}

// Model point → node index coordinates of the field's grid (where distances are in voxels).
Eigen::Vector3d ToIndex(const blob::FieldView& f, const Eigen::Vector3d& model) {
  const Eigen::Vector3d device = ModelToDevice(f).Apply(model);
  return (device - Eigen::Vector3d(f.origin_m[0], f.origin_m[1], f.origin_m[2])) / f.voxel_m;
}

void SphereDistances(const blob::FieldView& f, const Truth& truth, TrueDistanceGrid& out) {
  const Eigen::Vector3d c = ToIndex(f, truth.centre);
  const double r = f.fit_scale * truth.radius / f.voxel_m;
  const auto [nx, ny, nz] = out.dims;
  tbb::parallel_for(0, nx, [&, ny = ny, nz = nz](int i) {
    std::size_t n = static_cast<std::size_t>(i) * static_cast<std::size_t>(ny) * static_cast<std::size_t>(nz);
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < nz; ++k) out.voxels[n++] = static_cast<float>((Eigen::Vector3d(i, j, k) - c).norm() - r);
  });
}

std::expected<void, Error> MeshDistances(const blob::FieldView& f, const Truth& truth, TrueDistanceGrid& out) {
  if (!truth.open) {
    if (auto ok = CheckClosedOriented(truth.mesh, "truth mesh"); !ok) return ok;
  }
  TriangleMesh m;  // in node index coordinates, outward
  m.faces = truth.mesh.faces;
  m.vertices.reserve(truth.mesh.vertices.size());
  for (const auto& v : truth.mesh.vertices) m.vertices.push_back(ToIndex(f, v));
  OrientOutward(m);  // an open mesh too: its enclosed volume about any point still tells the side
  out.mesh_in_voxels = std::make_shared<const ExactMeshDistance>(m, !truth.open);
  const ExactMeshDistance& exact = *out.mesh_in_voxels;
  const auto [nx, ny, nz] = out.dims;
  const double reach = out.exact_within_voxels;

  // Candidates: nodes inside some face's bounding box grown by `reach`; every node within
  // `reach` of the surface is one.
  std::vector<std::uint8_t> near(out.voxels.size(), 0);
  const std::array<int, 3> dims = out.dims;
  for (const auto& t : m.faces) {
    const Eigen::Vector3d& a = m.vertices[static_cast<std::size_t>(t[0])];
    const Eigen::Vector3d& b = m.vertices[static_cast<std::size_t>(t[1])];
    const Eigen::Vector3d& c = m.vertices[static_cast<std::size_t>(t[2])];
    const Eigen::Vector3d lo = a.cwiseMin(b).cwiseMin(c).array() - reach;
    const Eigen::Vector3d hi = a.cwiseMax(b).cwiseMax(c).array() + reach;
    std::array<int, 3> l{};
    std::array<int, 3> h{};
    bool empty = false;
    for (int ax = 0; ax < 3; ++ax) {
      const auto a3 = static_cast<std::size_t>(ax);
      // Clamped before the cast: a mesh far outside the grid must not overflow int.
      l[a3] = static_cast<int>(std::clamp(std::ceil(lo[ax]), 0.0, static_cast<double>(dims[a3])));
      h[a3] = static_cast<int>(std::clamp(std::floor(hi[ax]), -1.0, static_cast<double>(dims[a3] - 1)));
      empty = empty || l[a3] > h[a3];
    }
    if (empty) continue;
    for (int i = l[0]; i <= h[0]; ++i)
      for (int j = l[1]; j <= h[1]; ++j) {
        const std::size_t row =
            (static_cast<std::size_t>(i) * static_cast<std::size_t>(ny) + static_cast<std::size_t>(j)) *
            static_cast<std::size_t>(nz);
        std::fill(near.begin() + static_cast<std::ptrdiff_t>(row) + l[2],
                  near.begin() + static_cast<std::ptrdiff_t>(row) + h[2] + 1, std::uint8_t{1});
      }
  }
  std::vector<std::size_t> candidates;
  for (std::size_t n = 0; n < near.size(); ++n)
    if (near[n]) candidates.push_back(n);
  near = {};

  // Unsigned distances: exact at candidates within `reach`, +∞ elsewhere.
  std::fill(out.voxels.begin(), out.voxels.end(), kInf);
  const auto snx = static_cast<std::size_t>(nx);
  const auto sny = static_cast<std::size_t>(ny);
  const auto snz = static_cast<std::size_t>(nz);
  auto node = [&](std::size_t n) {
    return Eigen::Vector3d(static_cast<double>(n / (sny * snz)), static_cast<double>((n / snz) % sny),
                           static_cast<double>(n % snz));
  };
  // Candidates are in grid order, so the previous closest point is a tight hint for the next.
  // simple_partitioner: chunk bounds, hence hint chains, hence results do not depend on threads.
  tbb::parallel_for(
      tbb::blocked_range<std::size_t>(0, candidates.size(), 256),
      [&](const auto& r) {
        Eigen::Vector3d hint = exact.AnySurfacePoint();
        for (std::size_t c = r.begin(); c != r.end(); ++c) {
          const double d = exact.UnsignedDistance(node(candidates[c]), hint);
          if (d <= reach) out.voxels[candidates[c]] = static_cast<float>(d);
        }
      },
      tbb::simple_partitioner());

  // Signs. A grid edge is 1 voxel long, so when both its nodes are more than ½ voxel from the
  // surface it cannot cross it: such nodes take one sign per 6-connected component (one
  // Side_of_triangle_mesh query each). Nodes within ½ voxel are queried one by one.
  constexpr float kHalf = 0.5f + 1e-4f;  // margin over the float rounding of d
  std::vector<std::int8_t> side(out.voxels.size(), 0);
  std::vector<std::size_t> close;
  for (const std::size_t n : candidates)
    if (out.voxels[n] <= kHalf) close.push_back(n);
  candidates = {};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, close.size(), 64), [&](const auto& r) {
    for (std::size_t c = r.begin(); c != r.end(); ++c)
      side[close[c]] =
          static_cast<std::int8_t>(truth.open ? exact.NearSide(node(close[c])) : exact.Side(node(close[c])));
  });
  for (const std::size_t n : close)
    if (side[n] == 0) side[n] = 2;  // on the surface: distance 0, any sign; 2 marks "done"
  if (truth.open) {
    // An open mesh does not separate inside from outside (the flood below would leak through a
    // hole): every node farther than ½ voxel takes the side of the mesh's generalized winding
    // number, from the fast dipole tree over its faces (centroid, area, unit normal; winding.h),
    // accurate beyond about a face's size.
    std::vector<Eigen::Vector3d> centres, normals;
    std::vector<double> areas;
    for (const auto& t : m.faces) {
      const Eigen::Vector3d& a = m.vertices[static_cast<std::size_t>(t[0])];
      const Eigen::Vector3d& b = m.vertices[static_cast<std::size_t>(t[1])];
      const Eigen::Vector3d& c = m.vertices[static_cast<std::size_t>(t[2])];
      const Eigen::Vector3d cross = (b - a).cross(c - a);
      const double twice_area = cross.norm();
      if (!(twice_area > 0)) continue;
      centres.push_back((a + b + c) / 3.0);
      normals.push_back(cross / twice_area);
      areas.push_back(0.5 * twice_area);
    }
    const field::WindingNumber winding(centres, normals, areas);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, side.size(), 4096), [&](const auto& r) {
      for (std::size_t n = r.begin(); n != r.end(); ++n)
        if (side[n] == 0) side[n] = static_cast<std::int8_t>(winding(node(n)) > 0.5 ? -1 : 1);
    });
  }
  std::vector<std::size_t> queue;
  for (std::size_t seed = 0; seed < out.voxels.size(); ++seed) {
    if (side[seed] != 0) continue;
    const auto value = static_cast<std::int8_t>(exact.Side(node(seed)) < 0 ? -1 : 1);
    side[seed] = value;
    queue.assign(1, seed);
    while (!queue.empty()) {
      const std::size_t n = queue.back();
      queue.pop_back();
      const std::size_t i = n / (sny * snz);
      const std::size_t j = (n / snz) % sny;
      const std::size_t k = n % snz;
      auto visit = [&](bool inside, std::size_t next) {
        if (inside && side[next] == 0) {  // every unset node is more than ½ voxel away
          side[next] = value;
          queue.push_back(next);
        }
      };
      visit(i > 0, n - sny * snz);
      visit(i + 1 < snx, n + sny * snz);
      visit(j > 0, n - snz);
      visit(j + 1 < sny, n + snz);
      visit(k > 0, n - 1);
      visit(k + 1 < snz, n + 1);
    }
  }
  for (std::size_t n = 0; n < out.voxels.size(); ++n)
    if (side[n] == -1)
      out.voxels[n] = -out.voxels[n];
    else if (side[n] == 2)
      out.voxels[n] = 0;
  return {};
}

}  // namespace

Truth Truth::Sphere(double radius, const Eigen::Vector3d& centre) {
  Truth t;
  t.kind = Kind::kSphere;
  t.radius = radius;
  t.centre = centre;
  return t;
}

Truth Truth::Mesh(TriangleMesh mesh) {
  Truth t;
  t.kind = Kind::kMesh;
  t.mesh = std::move(mesh);
  return t;
}

Truth Truth::OpenMesh(TriangleMesh mesh) {
  Truth t = Mesh(std::move(mesh));
  t.open = true;
  return t;
}

std::expected<TrueDistanceGrid, Error> TrueDistances(const blob::FieldView& field, const Truth& truth,
                                                     double exact_within_voxels) {
  if (!(exact_within_voxels >= 1))
    return std::unexpected(Error{fmt::format("exact_within_voxels must be at least 1, got {}", exact_within_voxels)});
  TrueDistanceGrid out;
  out.dims = field.dims;
  out.origin_m = Eigen::Vector3d(field.origin_m[0], field.origin_m[1], field.origin_m[2]);
  out.voxel_m = field.voxel_m;
  out.voxels.resize(NodeCount(field.dims));
  if (truth.kind == Truth::Kind::kSphere) {
    if (!(truth.radius > 0) || !std::isfinite(truth.radius))
      return std::unexpected(Error{fmt::format("sphere radius must be positive, got {}", truth.radius)});
    out.exact_within_voxels = std::numeric_limits<double>::infinity();
    SphereDistances(field, truth, out);
    return out;
  }
  out.exact_within_voxels = exact_within_voxels;
  if (auto ok = MeshDistances(field, truth, out); !ok) return std::unexpected(ok.error());
  return out;
}

namespace {

// The scoring shared by a field and a candidate mesh: phi(n) is the candidate's signed distance
// at node n (row-major, z fastest), voxels. The grid (dims, origin, voxel) is the truth's.
template <class Phi>
std::expected<EvalResult, Error> Score(const Phi& phi_at, const TrueDistanceGrid& truth, const EvalOptions& options) {
  if (!(options.band_voxels > 0) || options.band_voxels > truth.exact_within_voxels)
    return std::unexpected(Error{fmt::format("band {} voxels is outside (0, {}], where the truth is exact",
                                             options.band_voxels, truth.exact_within_voxels)});
  if (!(options.on_surface_voxels >= 0) || !(options.on_surface_voxels < options.gross_beyond_voxels))
    return std::unexpected(Error{fmt::format("on_surface_voxels {} must be in [0, gross_beyond_voxels {})",
                                             options.on_surface_voxels, options.gross_beyond_voxels)});
  if (!(options.far_beyond_voxels > 0) || options.far_beyond_voxels < options.gross_beyond_voxels)
    return std::unexpected(
        Error{fmt::format("far_beyond_voxels {} must be positive and at least gross_beyond_voxels {}",
                          options.far_beyond_voxels, options.gross_beyond_voxels)});
  EvalResult r;
  r.nodes = truth.voxels.size();
  std::vector<std::size_t> phantom;  // far wrong-sign nodes, outside and inside
  std::vector<std::size_t> hole;
  std::vector<float> abs_errors;
  double sum_abs = 0;
  double sum_signed = 0;
  std::size_t max_at = 0;
  const auto sny = static_cast<std::size_t>(truth.dims[1]);
  const auto snz = static_cast<std::size_t>(truth.dims[2]);
  for (std::size_t n = 0; n < r.nodes; ++n) {
    const double phi = phi_at(n);
    const double t = truth.voxels[n];
    const bool on_surface = std::abs(t) <= options.on_surface_voxels;
    const bool wrong = !on_surface && ((phi <= 0 && t > 0) || (phi > 0 && t < 0));
    if (std::abs(t) <= options.band_voxels) {
      r.on_surface_nodes += on_surface ? 1 : 0;
      const double e = phi - t;
      abs_errors.push_back(static_cast<float>(std::abs(e)));
      sum_abs += std::abs(e);
      sum_signed += e;
      if (std::abs(e) > r.max_abs_error) {
        r.max_abs_error = std::abs(e);
        max_at = n;
      }
      if (wrong) ++r.wrong_sign_in_band;
    }
    if (wrong && std::abs(t) > options.gross_beyond_voxels) ++r.gross_wrong_sign;
    if (wrong && std::abs(t) > options.far_beyond_voxels) (t > 0 ? phantom : hole).push_back(n);
  }
  r.band_nodes = abs_errors.size();
  if (r.band_nodes == 0) return std::unexpected(Error{"no grid node lies within the band of the true surface"});
  const double band = static_cast<double>(r.band_nodes);
  r.mean_abs_error = sum_abs / band;
  r.mean_signed_error = sum_signed / band;
  // Nearest rank: the smallest value with at least 99 % of the band at or below it.
  const auto rank = static_cast<std::size_t>(std::ceil(0.99 * band)) - 1;
  std::nth_element(abs_errors.begin(), abs_errors.begin() + static_cast<std::ptrdiff_t>(rank), abs_errors.end());
  r.p99_abs_error = abs_errors[rank];
  r.max_error_at_m = truth.origin_m + truth.voxel_m * Eigen::Vector3d(static_cast<double>(max_at / (sny * snz)),
                                                                      static_cast<double>((max_at / snz) % sny),
                                                                      static_cast<double>(max_at % snz));
  const auto at_m = [&](std::size_t n) {
    const std::array<double, 3> ijk = {static_cast<double>(n / (sny * snz)), static_cast<double>((n / snz) % sny),
                                       static_cast<double>(n % snz)};
    return Eigen::Vector3d(truth.origin_m + truth.voxel_m * Eigen::Vector3d(ijk[0], ijk[1], ijk[2]));
  };
  // Depths: the truth is exact where finite; beyond its exact reach (±∞) a mesh truth is asked
  // node by node (in parallel; each answer is exact, so the max does not depend on threads).
  const auto deepest = [&](const std::vector<std::size_t>& nodes, FarWrong& out) {
    std::vector<double> depth(nodes.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nodes.size(), 256), [&](const auto& range) {
      for (std::size_t c = range.begin(); c != range.end(); ++c) {
        const std::size_t n = nodes[c];
        double d = std::abs(static_cast<double>(truth.voxels[n]));
        if (!std::isfinite(d) && truth.mesh_in_voxels) {
          const Eigen::Vector3d ijk(static_cast<double>(n / (sny * snz)), static_cast<double>((n / snz) % sny),
                                    static_cast<double>(n % snz));
          d = truth.mesh_in_voxels->UnsignedDistance(ijk);
        }
        depth[c] = d;
      }
    });
    // A truth exact only within less than far_beyond_voxels (palpa eval on a v2 blob: 2) sent
    // nodes between its reach and far_beyond_voxels here as ±∞: count only the truly far ones.
    out.nodes = 0;
    for (std::size_t c = 0; c < nodes.size(); ++c) {
      if (!(depth[c] > options.far_beyond_voxels)) continue;
      ++out.nodes;
      if (options.list_far_nodes) out.listed.push_back({at_m(nodes[c]), depth[c]});
      if (depth[c] > out.deepest_voxels) {
        out.deepest_voxels = depth[c];
        out.deepest_at_m = at_m(nodes[c]);
      }
    }
  };
  deepest(phantom, r.phantom_solid);
  deepest(hole, r.holes);
  r.wrong_sign_in_band_percent = 100.0 * static_cast<double>(r.wrong_sign_in_band) / band;
  r.gross_wrong_sign_percent = 100.0 * static_cast<double>(r.gross_wrong_sign) / static_cast<double>(r.nodes);
  return r;
}

}  // namespace

std::expected<EvalResult, Error> Evaluate(const blob::FieldView& field, const TrueDistanceGrid& truth,
                                          const EvalOptions& options) {
  if (field.dims != truth.dims || field.voxel_m != truth.voxel_m || field.origin_m[0] != truth.origin_m.x() ||
      field.origin_m[1] != truth.origin_m.y() || field.origin_m[2] != truth.origin_m.z())
    return std::unexpected(Error{"the truth was computed on another grid (dims, origin or voxel differ)"});
  // Beyond the exact band, scoring would score the clamp.
  if (options.band_voxels > ExactBandVoxels(field))
    return std::unexpected(
        Error{fmt::format("band {} voxels exceeds the field's narrow band ({} voxels inside, {} outside)",
                          options.band_voxels, field.band_voxels, field.band_outside)});
  const auto sny = static_cast<std::size_t>(field.dims[1]);
  const auto snz = static_cast<std::size_t>(field.dims[2]);
  return Score(
      [&](std::size_t n) {
        // v1 in its dense payload; v2 read in place, node by node.
        const blob::DenseAccessor* dense = field.dense();
        const std::int32_t q = dense != nullptr ? dense->data()[n]
                                                : field.NodeQ16(static_cast<std::int32_t>(n / (sny * snz)),
                                                                static_cast<std::int32_t>((n / snz) % sny),
                                                                static_cast<std::int32_t>(n % snz));
        return static_cast<double>(q) / 65536.0;
      },
      truth, options);
}

std::expected<EvalResult, Error> EvaluateCandidate(const TrueDistanceGrid& candidate, const TrueDistanceGrid& truth,
                                                   const EvalOptions& options) {
  if (candidate.dims != truth.dims || candidate.voxel_m != truth.voxel_m || candidate.origin_m != truth.origin_m)
    return std::unexpected(Error{"the candidate was computed on another grid (dims, origin or voxel differ)"});
  if (!candidate.mesh_in_voxels)
    return std::unexpected(Error{"the candidate must be a mesh (its distance is needed beyond its own band)"});
  const auto sny = static_cast<std::size_t>(truth.dims[1]);
  const auto snz = static_cast<std::size_t>(truth.dims[2]);
  return Score(
      [&](std::size_t n) {
        const double c = candidate.voxels[n];
        if (std::isfinite(c)) return c;
        // Beyond the candidate's exact reach only its sign is stored; a band node of the truth
        // may lie there when the candidate is far off, so ask the exact distance.
        if (!(std::abs(static_cast<double>(truth.voxels[n])) <= options.band_voxels)) return c;
        const Eigen::Vector3d ijk(static_cast<double>(n / (sny * snz)), static_cast<double>((n / snz) % sny),
                                  static_cast<double>(n % snz));
        return std::copysign(candidate.mesh_in_voxels->UnsignedDistance(ijk), c);
      },
      truth, options);
}

std::expected<EvalResult, Error> Evaluate(const blob::FieldView& field, const Truth& truth,
                                          const EvalOptions& options) {
  auto grid = TrueDistances(field, truth, std::max(1.0, options.band_voxels));
  if (!grid) return std::unexpected(grid.error());
  return Evaluate(field, *grid, options);
}

}  // namespace palpa::mesh
