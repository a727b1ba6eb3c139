#include "palpa/field/samples.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <limits>
#include <numbers>
#include <numeric>
#include <vector>

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <Eigen/Eigenvalues>

#include "palpa/field/winding.h"
#include "point_cloud.h"

namespace palpa::field {
namespace {

// Keeps the samples whose `drop` is 0, in order (positions, normals and, when present, the file
// lines that name them); returns how many are kept.
std::size_t Compact(PointSet& points, const std::vector<std::uint8_t>& drop) {
  const std::size_t n = points.positions.size();
  const bool lines = points.lines.size() == n;
  std::size_t w = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (drop[i]) continue;
    points.positions[w] = points.positions[i];
    points.normals[w] = points.normals[i];
    if (lines) points.lines[w] = points.lines[i];
    ++w;
  }
  points.positions.resize(w);
  points.normals.resize(w);
  if (lines) points.lines.resize(w);
  return w;
}

}  // namespace

std::string DroppedSamples::Describe() const {
  std::string out;
  if (bad_normals > 0) {
    out = fmt::format("{} sample{} with a zero-length or non-finite normal (first: {})", bad_normals,
                      bad_normals == 1 ? "" : "s", first_bad_normal_place);
  }
  if (duplicates > 0) {
    if (!out.empty()) out += " and ";
    out += fmt::format("{} exact duplicate{} (first: {}, the position of {})", duplicates, duplicates == 1 ? "" : "s",
                       first_duplicate_place, duplicate_of_place);
  }
  return out;
}

DroppedSamples DropDegenerateSamples(PointSet& points, const std::string& file) {
  const std::size_t n = points.positions.size();
  DroppedSamples d;
  std::vector<std::uint8_t> drop(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    if (points.normals[i] == Eigen::Vector3d::Zero()) {
      drop[i] = 1;
      ++d.bad_normals;
      if (!d.first_bad_normal) d.first_bad_normal = i;
    }
  }
  // Exact duplicates: sort indices by position (ties by index), so each run of equal positions
  // starts with its earliest point; every later one in the run is dropped.
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t{0});
  const auto& p = points.positions;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    for (Eigen::Index ax = 0; ax < 3; ++ax)
      if (p[a][ax] != p[b][ax]) return p[a][ax] < p[b][ax];
    return a < b;
  });
  std::size_t run_first = n;  // first point of the current run with a usable normal
  for (std::size_t r = 0; r < n; ++r) {
    const std::size_t i = order[r];
    if (r == 0 || p[i] != p[order[r - 1]]) run_first = n;
    if (drop[i]) continue;  // already dropped for its normal
    if (run_first == n) {
      run_first = i;
      continue;
    }
    drop[i] = 1;
    ++d.duplicates;
    if (!d.first_duplicate || i < *d.first_duplicate) {
      d.first_duplicate = i;
      d.duplicate_of = run_first;
    }
  }
  if (d.first_bad_normal) d.first_bad_normal_place = PointPlace(file, points, *d.first_bad_normal);
  if (d.first_duplicate) {
    d.first_duplicate_place = PointPlace(file, points, *d.first_duplicate);
    d.duplicate_of_place = PointPlace(file, points, *d.duplicate_of);
  }
  d.kept = Compact(points, drop);
  return d;
}

namespace {
constexpr std::size_t kPlaneNeighbours = 16;
constexpr std::size_t kSpacingNeighbour = 8;
constexpr double kNoiseFactor = 4.0;
constexpr double kOffsetSpacings = 0.5;
constexpr double kIsolatedSpacings = 1.5;
constexpr std::size_t kMinAgreeing = 4;   // of kPlaneNeighbours
constexpr std::size_t kMinOwnSide = 1;    // agreeing neighbours before a wall's other side counts
constexpr std::size_t kMinOtherSide = 4;  // ... and neighbours on that side
constexpr double kSparseSpacings = 3.0;   // 16th neighbour (~1.4 s on a surface, ~2 s on a rim)
constexpr double kMaxLocalSpacing = 2.0;  // x the global: outliers among outliers are not a sparse region
}  // namespace

StraySamples FindStraySamples(const std::vector<Eigen::Vector3d>& positions,
                              const std::vector<Eigen::Vector3d>& normals) {
  StraySamples out;
  const std::size_t n = positions.size();
  if (n < kPlaneNeighbours + 1) return out;
  const detail::PointCloud cloud{&positions};
  const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  // Neighbours of every sample, without itself (an exact duplicate may come first instead: same
  // position, so it makes no difference to the plane).
  std::vector<std::size_t> nb(n * kPlaneNeighbours);
  std::vector<double> spacing(n), nearest(n), farthest(n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    std::array<std::size_t, kPlaneNeighbours + 1> idx{};
    std::array<double, kPlaneNeighbours + 1> d2{};
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      tree.knnSearch(positions[i].data(), kPlaneNeighbours + 1, idx.data(), d2.data());
      std::size_t m = 0;
      for (std::size_t t = 0; t <= kPlaneNeighbours && m < kPlaneNeighbours; ++t)
        if (idx[t] != i) nb[i * kPlaneNeighbours + m++] = idx[t];
      spacing[i] = std::sqrt(d2[kSpacingNeighbour]);
      nearest[i] = std::sqrt(d2[1]);
      farthest[i] = std::sqrt(d2[kPlaneNeighbours]);
    }
  });
  const double s = detail::Median(spacing);
  out.spacing = s;
  if (!(s > 0.0)) return out;
  std::vector<double> excess(n, -1.0);  // offset in spacings when stray, else -1
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 256), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const detail::LeastVariancePlane plane = detail::FitLeastVariancePlane(
          positions, &nb[i * kPlaneNeighbours], kPlaneNeighbours, [](std::size_t) { return 1.0; });
      const double rms = std::sqrt(std::max(plane.variance, 0.0) / static_cast<double>(kPlaneNeighbours));
      const double offset = std::abs(plane.normal.dot(positions[i] - plane.centre));
      // The spacing where P is: the median of its neighbours' own (a sparse region of a real scan
      // is not an outlier; a sample far from a normally dense surface is).
      std::array<double, kPlaneNeighbours> around{};
      for (std::size_t m = 0; m < kPlaneNeighbours; ++m) around[m] = spacing[nb[i * kPlaneNeighbours + m]];
      std::nth_element(around.begin(), around.begin() + kPlaneNeighbours / 2, around.end());
      const double local = std::clamp(around[kPlaneNeighbours / 2], s, kMaxLocalSpacing * s);
      std::size_t agree = 0, wall = 0;
      for (std::size_t m = 0; m < kPlaneNeighbours; ++m) {
        const std::size_t j = nb[i * kPlaneNeighbours + m];
        const Eigen::Vector3d chord = positions[j] - positions[i];
        if (normals[j].dot(normals[i]) > 0.0)
          ++agree;
        else if (detail::EachBehindTheOther(chord, normals[i], normals[j], detail::kThinWallSin))
          ++wall;
      }
      // The other side of a wall thinner than the spacing supports P as its own side does: a
      // thin flange's narrow face has most of its 16 nearest on the wide face behind it (the
      // spool's clean 5,000 samples lost 43 here, and the wide face's inner balls then filled the
      // flange's concave corner with phantom solid). A flipped or random normal's neighbours on
      // one smooth sheet are not each behind the other (detail::EachBehindTheOther). An outlier
      // buried under a surface and facing into it has the surface behind it too, but few or none
      // of its own side: over the 2 % outlier rows of 27 meshes (seed 1) the other side alone
      // would keep 143 outliers and 224 true samples; with kMinOwnSide and kMinOtherSide, 42 and 205.
      // One of its own side is enough: a sparse face's sample beside a convex corner has one, and
      // the two other faces there, each behind its plane (a cube, 1,000 random samples: 2 top
      // samples dropped, 610 phantom nodes 7 voxels up; 2 own: 18 outliers kept and 186 true).
      if (agree >= kMinOwnSide && wall >= kMinOtherSide) agree += wall;
      if (offset > kNoiseFactor * rms + kOffsetSpacings * local || nearest[i] > kIsolatedSpacings * local ||
          farthest[i] > kSparseSpacings * local || agree < kMinAgreeing)
        excess[i] = std::max(offset, nearest[i]) / local;
    }
  });
  for (std::size_t i = 0; i < n; ++i) {
    if (excess[i] < 0.0) continue;
    out.indices.push_back(i);
    if (!out.farthest || excess[i] > out.farthest_spacings) {
      out.farthest = i;
      out.farthest_spacings = excess[i];
    }
  }
  return out;
}

void RemoveSamples(PointSet& points, const std::vector<std::size_t>& indices) {
  std::vector<std::uint8_t> drop(points.positions.size(), 0);
  for (const std::size_t i : indices) drop[i] = 1;
  Compact(points, drop);
}

Simplification SimplifyDenseSamples(PointSet& points, double cell) {
  const std::size_t n = points.positions.size();
  Simplification out{n, n, cell};
  if (n < 2 || !(cell > 0)) return out;
  // Cell coordinates relative to the lowest corner; a key sorts by cell then sample.
  Eigen::Vector3d lo = points.positions[0];
  for (const Eigen::Vector3d& p : points.positions) lo = lo.cwiseMin(p);
  std::vector<std::array<std::int64_t, 3>> key(n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i)
      for (Eigen::Index a = 0; a < 3; ++a)
        // Clamped: a far outlier's cell number must not overflow (it stays a cell of its own).
        key[i][static_cast<std::size_t>(2 - a)] =
            static_cast<std::int64_t>(std::min(std::floor((points.positions[i][a] - lo[a]) / cell), 0x1p62));
  });
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return key[a] != key[b] ? key[a] < key[b] : a < b; });
  std::size_t cells = 1;
  for (std::size_t r = 1; r < n; ++r) cells += key[order[r]] != key[order[r - 1]] ? 1u : 0u;
  if (2 * cells > n) return out;  // not denser than the grid: leave the set as it was

  const bool lines = points.lines.size() == n;
  PointSet merged;
  merged.has_normals = points.has_normals;
  merged.positions.reserve(cells);
  merged.normals.reserve(cells);
  struct Group {
    Eigen::Vector3d first_normal, position_sum, normal_sum;
    std::size_t count, first;
  };
  std::vector<Group> groups;
  for (std::size_t begin = 0; begin < n;) {
    std::size_t end = begin + 1;
    while (end < n && key[order[end]] == key[order[begin]]) ++end;
    groups.clear();
    for (std::size_t r = begin; r < end; ++r) {
      const std::size_t i = order[r];
      const Eigen::Vector3d& nrm = points.normals[i];
      auto g =
          std::find_if(groups.begin(), groups.end(), [&](const Group& x) { return x.first_normal.dot(nrm) >= 0.7; });
      if (g == groups.end()) {
        groups.push_back(Group{nrm, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 0, i});
        g = groups.end() - 1;
      }
      g->position_sum += points.positions[i];
      g->normal_sum += nrm;
      ++g->count;
    }
    for (const Group& g : groups) {
      merged.positions.push_back(g.position_sum / static_cast<double>(g.count));
      const double length = g.normal_sum.norm();
      merged.normals.push_back(length > 0 ? Eigen::Vector3d(g.normal_sum / length) : g.first_normal);
      if (lines) merged.lines.push_back(points.lines[g.first]);
    }
    begin = end;
  }
  out.after = merged.positions.size();
  points = std::move(merged);
  return out;
}

Simplification SimplifyBarePositions(PointSet& points, double voxel) {
  points.normals.assign(points.positions.size(), Eigen::Vector3d::UnitZ());
  const Simplification half = SimplifyDenseSamples(points, 0.5 * voxel);
  return half.Applied() ? half : SimplifyDenseSamples(points, kDenseCellVoxels * voxel);
}

WindingOutliers FindWindingOutliers(const std::vector<Eigen::Vector3d>& positions,
                                    const std::vector<Eigen::Vector3d>& normals, double min_jump) {
  constexpr double kSureOutlierJump = 0.0;
  constexpr double kPlaneOffset = 0.2;  // x the 16th neighbour's distance
  WindingOutliers out;
  const std::size_t n = positions.size();
  constexpr std::size_t kNeighbours = 16;
  if (n <= kNeighbours || normals.size() != n) return out;
  std::vector<double> jump = SampleProbes(positions, normals).Jumps(normals);
  const detail::PointCloud cloud{&positions};
  const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 64), [&](const auto& r) {
    std::array<std::size_t, kNeighbours + 1> idx{};
    std::array<double, kNeighbours + 1> d2{};
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const Eigen::Vector3d& p = positions[i];
      const Eigen::Vector3d& nrm = normals[i];
      if (jump[i] < kSureOutlierJump || !(jump[i] < min_jump)) continue;
      const std::size_t got = tree.knnSearch(p.data(), kNeighbours + 1, idx.data(), d2.data());
      // Between the two: next to a sharp edge or a fin the jump of a true sample is low too, but
      // it lies on the plane of the neighbours that share its normal (fandisk: offsets below
      // 0.02 x the 16th neighbour's distance); an outlier does not, or has no such neighbours.
      Eigen::Vector3d centre = Eigen::Vector3d::Zero(), mean_normal = Eigen::Vector3d::Zero();
      int agree = 0;
      for (std::size_t m = 0; m < got; ++m) {
        if (idx[m] == i || normals[idx[m]].dot(nrm) < 0.8) continue;
        centre += positions[idx[m]];
        mean_normal += normals[idx[m]];
        ++agree;
      }
      if (agree < 2) continue;  // no neighbour shares its normal: an outlier
      centre /= agree;
      const Eigen::Vector3d plane_normal = mean_normal.normalized();
      double noise2 = 0;  // the agreeing neighbours' own mean square offset: noise widens the test
      for (std::size_t m = 0; m < got; ++m) {
        if (idx[m] == i || normals[idx[m]].dot(nrm) < 0.8) continue;
        const double o = (positions[idx[m]] - centre).dot(plane_normal);
        noise2 += o * o;
      }
      const double offset = std::abs((p - centre).dot(plane_normal));
      if (offset <= std::max(kPlaneOffset * std::sqrt(d2[got - 1]), 3.0 * std::sqrt(noise2 / agree)))
        jump[i] = min_jump;
    }
  });
  for (std::size_t i = 0; i < n; ++i) {
    if (!(jump[i] < min_jump)) continue;
    out.indices.push_back(i);
    if (!out.worst || jump[i] < out.worst_jump) {
      out.worst = i;
      out.worst_jump = jump[i];
    }
  }
  return out;
}

namespace {

constexpr double kMaxMoveNoise = 2.5;
constexpr double kShapeGrowth2 = 4.0;  // the squared growth of a shape's residual, 16 -> 48 neighbours
// The bisector move (SmoothNoisyPositions). Its neighbourhood is chosen per sample among the
// 16, 32 and 64 nearest by the intersection of confidence intervals (Katkovnik's LPA-ICI): the
// mean over the larger neighbourhood is taken while its interval, mean +- kIciWidth x noise /
// sqrt(count), still meets every smaller one's; a turning surface moves the mean out of them.
// Noise rows of knot1, fandisk, sphere, CGAL's bull and femur (150 cells, sigma = 0.5 / 1 voxel)
// and data/sphere_20k_normal.xyz (noise ~1.6 sample spacings, 22-degree normal noise): 16 alone
// is best on the bull and 48-64 on the sphere; a width of 1 or 2 loses one or the other, 1.25
// keeps both (docs/field-methods.md § Noise: the bisector move). A full step (1 instead of 1/2)
// moves each sample by its neighbours' noise too (bull 0.27 -> 0.31 voxel RMS at 16).
constexpr std::size_t kBisectorMinNeighbours = kMoveFewestNeighbours;
constexpr std::size_t kBisectorMaxNeighbours = kMoveMostNeighbours;
constexpr double kIciWidth = 1.25;
constexpr double kBisectorCos = 0.5;  // within 60 degrees: a sharp edge's other face never
constexpr double kBisectorStep = 0.5;

// The noise measure of SmoothNoisyPositions (NoiseSmoothing::noise and ::residual).
NoiseSmoothing MeasureNoise(const std::vector<Eigen::Vector3d>& positions, const std::vector<Eigen::Vector3d>& normals,
                            const detail::KdTree& tree, std::size_t neighbours) {
  constexpr double kAgreeCos = 0.8;
  constexpr int kMinFit = 8;
  // The noise is measured on small neighbourhoods, where a smooth surface is a quadric to well
  // below a voxel (coarse or faceted samples included) and only noise is left in the residual.
  constexpr std::size_t kNoiseNeighbours = 16;
  NoiseSmoothing out;
  const std::size_t n = positions.size();
  std::vector<double> residual(n, -1.0), wide_residual(n, -1.0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 64), [&](const auto& r) {
    std::vector<std::size_t> idx(neighbours + 1);
    std::vector<double> d2(neighbours + 1);
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const Eigen::Vector3d& p = positions[i];
      const Eigen::Vector3d& nrm = normals[i];
      const std::size_t got = tree.knnSearch(p.data(), neighbours + 1, idx.data(), d2.data());
      const double scale = std::sqrt(d2[got - 1]);  // u, v, z in units of the neighbourhood
      if (!(scale > 0)) continue;
      // Over the first `count` neighbours (nearest first, the sample itself included), those
      // whose normals agree.
      const auto fit = [&](std::size_t count) {
        return detail::QuadricResidual(positions, idx.data(), count, p, nrm, scale, kMinFit + 1,
                                       [&](std::size_t j) { return normals[j].dot(nrm) >= kAgreeCos; });
      };
      residual[i] = fit(std::min(got, kNoiseNeighbours + 1));
      wide_residual[i] = fit(got);
    }
  });
  // Over the samples fitted (a residual of -1: too few agreeing normals); -1 when none was.
  const auto median = [](const std::vector<double>& values) {
    std::vector<double> fitted;
    fitted.reserve(values.size());
    std::copy_if(values.begin(), values.end(), std::back_inserter(fitted), [](double x) { return x >= 0; });
    return fitted.empty() ? -1.0 : detail::Median(std::move(fitted));
  };
  out.residual = median(residual);
  if (out.residual < 0) {
    out.residual = 0;
    return out;
  }
  // Noise leaves the same residual at both scales; a shape finer than the fit (sparse samples of a
  // detailed surface: bull with 1,000 samples, oni) leaves more at the wider one, which holds ~3x
  // the samples (a radius ~sqrt(3) wider). Taking that part as growing 2x (measured on clean sets:
  // 1.6-2.8x; noise alone: 1.05-1.15x), r16^2 = s^2 + e^2 and r48^2 = s^2 + 4 e^2 leave the noise
  // s^2 = (4 r16^2 - r48^2) / 3.
  const double wide = median(wide_residual);
  out.noise = wide < 0 ? out.residual
                       : std::sqrt(std::max(
                             0.0, (kShapeGrowth2 * out.residual * out.residual - wide * wide) / (kShapeGrowth2 - 1.0)));
  return out;
}

// One Jacobi pass of the bisector move: the offset of each sample along its normal, from the
// positions as they were (`tree` indexes them); `noise` sets the confidence intervals, `cap`
// bounds each move.
void BisectorPass(std::vector<Eigen::Vector3d>& positions, const std::vector<Eigen::Vector3d>& normals,
                  const detail::KdTree& tree, double noise, double cap) {
  const std::size_t n = positions.size();
  std::vector<double> move(n, std::numeric_limits<double>::quiet_NaN());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 64), [&](const auto& r) {
    std::array<std::size_t, kBisectorMaxNeighbours + 1> idx{};
    std::array<double, kBisectorMaxNeighbours + 1> d2{};
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const Eigen::Vector3d& p = positions[i];
      const Eigen::Vector3d& nrm = normals[i];
      const std::size_t got = tree.knnSearch(p.data(), idx.size(), idx.data(), d2.data());
      double sum = 0.0;
      int used = 0;
      double lo = -std::numeric_limits<double>::infinity(), hi = std::numeric_limits<double>::infinity();
      double chosen = std::numeric_limits<double>::quiet_NaN();
      std::size_t test_at = kBisectorMinNeighbours;  // idx[0..test_at]: itself and its nearest 16, 32, 64
      for (std::size_t m = 0; m < got; ++m) {
        const std::size_t j = idx[m];
        const double c = normals[j].dot(nrm);
        if (j != i && c >= kBisectorCos) {
          sum += (nrm + normals[j]).dot(positions[j] - p) / (1.0 + c);
          ++used;
        }
        if (m != test_at && m + 1 != got) continue;
        test_at *= 2;
        if (used < 2) continue;
        const double mean = sum / used, half = kIciWidth * noise / std::sqrt(static_cast<double>(used));
        lo = std::max(lo, mean - half);
        hi = std::min(hi, mean + half);
        if (lo > hi && !std::isnan(chosen)) break;
        chosen = mean;
      }
      if (!std::isnan(chosen)) move[i] = std::clamp(kBisectorStep * chosen, -cap, cap);
    }
  });
  for (std::size_t i = 0; i < n; ++i)
    if (!std::isnan(move[i])) positions[i] += move[i] * normals[i];
}

}  // namespace

NoiseSmoothing SmoothNoisyPositions(std::vector<Eigen::Vector3d>& positions,
                                    const std::vector<Eigen::Vector3d>& normals, std::size_t neighbours,
                                    double threshold, int passes) {
  constexpr std::size_t kMinNeighbours = 8;
  const std::size_t n = positions.size();
  if (n <= neighbours || normals.size() != n || neighbours < kMinNeighbours) return {};
  const detail::PointCloud cloud{&positions};
  NoiseSmoothing out;
  std::vector<Eigen::Vector3d> before;
  // Each pass indexes the positions the previous one left; the first, the measure's.
  for (int pass = 0; pass < std::max(passes, 1); ++pass) {
    const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
    if (pass == 0) {
      out = MeasureNoise(positions, normals, tree, neighbours);
      if (!(out.noise > threshold)) return out;
      before = positions;
    }
    // A move beyond kMaxMoveNoise x the residual is the shape (a detail finer than the
    // neighbours), not noise.
    if (pass < passes) BisectorPass(positions, normals, tree, out.residual, kMaxMoveNoise * out.residual);
  }
  double total = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double d = (positions[i] - before[i]).norm();
    if (d > 0) {
      total += d;
      ++out.moved;
    }
  }
  out.mean_move = out.moved > 0 ? total / static_cast<double>(out.moved) : 0.0;
  out.passes = std::max(passes, 0);
  return out;
}

}  // namespace palpa::field
