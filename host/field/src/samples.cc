#include "palpa/field/samples.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <limits>
#include <numbers>
#include <numeric>
#include <optional>
#include <span>
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

// A sample's cube cell (z, y, x) relative to the lowest corner of the set; with the samples in
// order of cell, then index, and where each occupied cell's run of that order starts.
using CellKey = std::array<std::int64_t, 3>;
struct CellOrder {
  std::vector<CellKey> key;  // per sample
  std::vector<std::size_t> order;
  std::vector<std::size_t> start;  // per occupied cell, then order.size()
  std::size_t Cells() const { return start.size() - 1; }
  const CellKey& KeyOf(std::size_t c) const { return key[order[start[c]]]; }
};

CellOrder SortIntoCells(const std::vector<Eigen::Vector3d>& positions, double cell) {
  const std::size_t n = positions.size();
  CellOrder out;
  Eigen::Vector3d lo = positions[0];
  for (const Eigen::Vector3d& p : positions) lo = lo.cwiseMin(p);
  out.key.resize(n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 4096), [&](const auto& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i)
      for (Eigen::Index a = 0; a < 3; ++a)
        // Clamped: a far outlier's cell number must not overflow (it stays a cell of its own).
        out.key[i][static_cast<std::size_t>(2 - a)] =
            static_cast<std::int64_t>(std::min(std::floor((positions[i][a] - lo[a]) / cell), 0x1p62));
  });
  out.order.resize(n);
  std::iota(out.order.begin(), out.order.end(), std::size_t{0});
  std::sort(out.order.begin(), out.order.end(),
            [&](std::size_t a, std::size_t b) { return out.key[a] != out.key[b] ? out.key[a] < out.key[b] : a < b; });
  for (std::size_t r = 0; r < n; ++r)
    if (r == 0 || out.key[out.order[r]] != out.key[out.order[r - 1]]) out.start.push_back(r);
  out.start.push_back(n);
  return out;
}

// The smallest gap, in units of the cell, that splits a cell's samples into two layers, whatever
// the noise: the two sides of a wall 0.3 voxels thick, in cells of kDenseCellVoxels.
constexpr double kLeastLayerGapCells = 0.2;
// A gap splits only beyond this many times the noise (the median RMS within the layers).
constexpr double kLayerGapNoises = 4.0;
// And only between two layers of this many samples or more, each flat: its spread along the
// normal under 1 / kLayerGapSpreads of the gap.
constexpr std::size_t kLeastLayerSamples = 2;
constexpr double kLayerGapSpreads = 2.0;

// For SimplifyBarePositions' wide cells: the cells whose samples fall in two layers along the
// normal of the 3 x 3 x 3 cells around it, split at their widest gap (the rules: samples.h,
// docs/field-methods.md § Bare dense sets). The normal is PCA's least axis, taken again about each
// layer's own mean where the neighbourhood has two layers (layers whose tangential means differ
// tilt the axis of the whole). The flatness test keeps a single sheet that the axis tilts next to
// an edge out: its offsets spread evenly (CGAL's anchor, 60,000 samples at 100 cells: 0.66 -> 0.84 %
// of the band wrong when such cells were split). Deterministic.
struct WallCells {
  std::vector<std::uint8_t> in_wall;  // per sample: its cell holds both sides
  std::size_t cells = 0;
  double noise = 0;  // the median RMS within the neighbourhoods' layers, units of the positions
};

WallCells ThinWallCells(const std::vector<Eigen::Vector3d>& positions, const CellOrder& sorted, double cell) {
  const std::size_t n = positions.size();
  WallCells out;
  out.in_wall.assign(n, 0);
  const std::vector<std::size_t>& start = sorted.start;
  const std::size_t cells = sorted.Cells();
  const auto cell_of = [&](const CellKey& k) -> std::size_t {  // cells when empty
    const auto at = std::lower_bound(start.begin(), start.end() - 1, k,
                                     [&](std::size_t r, const CellKey& x) { return sorted.key[sorted.order[r]] < x; });
    const auto c = static_cast<std::size_t>(at - start.begin());
    return c < cells && sorted.KeyOf(c) == k ? c : cells;
  };
  struct Split {
    std::size_t at = 0;  // the cell's sorted offsets [0, at) lie below its widest gap
    double gap = 0;
    double rms = -1;  // the neighbourhood's, within its layers; < 0: too few samples
    // The neighbourhood's own widest gap, [low, high] in the cell's offsets, where it parts two
    // flat layers (as two_flat_layers, 3 samples a layer or more); else empty (low > high).
    double low = 1, high = 0;
  };
  std::vector<Split> split(cells);
  const auto two_flat_layers = [](const Split& s, const std::vector<std::pair<double, std::size_t>>& off) {
    const std::size_t count = off.size();
    if (s.at < kLeastLayerSamples || count - s.at < kLeastLayerSamples) return false;
    const double spread = std::max(off[s.at - 1].first - off[0].first, off[count - 1].first - off[s.at].first);
    return s.gap > kLayerGapSpreads * spread;
  };
  std::vector<std::vector<std::pair<double, std::size_t>>> offsets(cells);
  // The normal of a scatter matrix: its least axis (PCA); zero where undefined.
  const auto least_axis = [](const Eigen::Matrix3d& scatter) -> Eigen::Vector3d {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(scatter);
    return eigen.info() == Eigen::Success && scatter.allFinite() ? Eigen::Vector3d(eigen.eigenvectors().col(0))
                                                                 : Eigen::Vector3d::Zero();
  };
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells, 256), [&](const auto& range) {
    std::vector<std::size_t> around;
    std::vector<Eigen::Vector3d> near;                  // the neighbourhood's samples, about origin
    std::vector<std::pair<double, std::size_t>> along;  // their offsets, sorted, and index in near
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      const std::size_t count = start[c + 1] - start[c];
      if (count < 2) continue;
      const CellKey& k = sorted.KeyOf(c);
      around.clear();
      for (std::int64_t dz = -1; dz <= 1; ++dz)
        for (std::int64_t dy = -1; dy <= 1; ++dy)
          for (std::int64_t dx = -1; dx <= 1; ++dx) {
            const std::size_t m = cell_of(CellKey{k[0] + dz, k[1] + dy, k[2] + dx});
            if (m != cells) around.push_back(m);
          }
      // About the cell's own first sample: a far outlier elsewhere costs no precision here.
      const Eigen::Vector3d origin = positions[sorted.order[start[c]]];
      near.clear();
      for (const std::size_t m : around)
        for (std::size_t r = start[m]; r < start[m + 1]; ++r) near.push_back(positions[sorted.order[r]] - origin);
      const std::size_t total = near.size();
      // Scatter about each layer's own mean: [0, at) and [at, total) of `along` (at = 0: one).
      const auto pooled_scatter = [&](std::size_t at) {
        Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
        for (const auto& [b, e] : {std::pair{std::size_t{0}, at}, std::pair{at, total}}) {
          if (b == e) continue;
          detail::AddScatter(
              e - b,
              [&, b = b](std::size_t m) -> const Eigen::Vector3d& {
                return near[along.empty() ? b + m : along[b + m].second];
              },
              detail::UnitWeight, scatter);
        }
        return scatter;
      };
      std::size_t at = 0;  // the neighbourhood's widest gap: along[at - 1] .. along[at]
      double widest = 0;
      const auto widest_gap = [&](const Eigen::Vector3d& normal) {
        along.clear();
        for (std::size_t j = 0; j < total; ++j) along.emplace_back(near[j].dot(normal), j);
        std::sort(along.begin(), along.end());
        at = 0;
        widest = 0;
        for (std::size_t j = 1; j < total; ++j)
          if (along[j].first - along[j - 1].first > widest) {
            widest = along[j].first - along[j - 1].first;
            at = j;
          }
      };
      along.clear();
      Eigen::Vector3d normal = least_axis(pooled_scatter(0));
      if (normal.isZero()) continue;
      widest_gap(normal);
      bool layered = at >= 3 && total - at >= 3;
      // Two layers whose tangential means differ tilt the whole neighbourhood's axis; the axis of
      // the layers' pooled scatter is their common normal.
      if (layered) {
        const Eigen::Vector3d pooled = least_axis(pooled_scatter(at));
        if (!pooled.isZero()) {
          normal = pooled;
          widest_gap(normal);
          layered = at >= 3 && total - at >= 3;
        }
      }
      auto& off = offsets[c];
      for (std::size_t r = start[c]; r < start[c + 1]; ++r)
        off.emplace_back((positions[sorted.order[r]] - origin).dot(normal), sorted.order[r]);
      std::sort(off.begin(), off.end());
      Split& s = split[c];
      for (std::size_t j = 1; j < count; ++j)
        if (off[j].first - off[j - 1].first > s.gap) {
          s.gap = off[j].first - off[j - 1].first;
          s.at = j;
        }
      // The noise: the RMS offset within the two layers of the whole neighbourhood (split at its
      // widest gap where each side has 3 samples or more), so a thin wall is no noise; a cell's
      // own few samples would understate it (knot1 with 1 voxel of noise: a quarter of that).
      if (total < 8) continue;  // too few to say how noisy the samples are
      const auto square_sum = [&](std::size_t b, std::size_t e) {
        double m = 0, q = 0;
        for (std::size_t j = b; j < e; ++j) m += along[j].first;
        m /= static_cast<double>(e - b);
        for (std::size_t j = b; j < e; ++j) q += (along[j].first - m) * (along[j].first - m);
        return q;
      };
      s.rms = std::sqrt((layered ? square_sum(0, at) + square_sum(at, total) : square_sum(0, total)) /
                        static_cast<double>(total));
      if (layered && widest > kLayerGapSpreads * std::max(along[at - 1].first - along[0].first,
                                                          along[total - 1].first - along[at].first)) {
        s.low = along[at - 1].first;
        s.high = along[at].first;
      }
    }
  });
  std::vector<double> rms;
  for (const Split& s : split)
    if (s.rms >= 0) rms.push_back(s.rms);
  double noise = 0;
  if (!rms.empty()) {
    std::nth_element(rms.begin(), rms.begin() + static_cast<std::ptrdiff_t>(rms.size() / 2), rms.end());
    noise = rms[rms.size() / 2];
  }
  out.noise = noise;
  const double least_gap = std::max(kLeastLayerGapCells * cell, kLayerGapNoises * noise);
  for (std::size_t c = 0; c < cells; ++c) {
    const Split& s = split[c];
    if (s.at == 0 || !(s.gap > least_gap)) continue;
    // Two flat layers in the cell, or a sample alone on one side of the gap that parts two flat
    // layers of the neighbourhood (a wall's side may have one sample in a cell).
    const bool parts_neighbourhood = s.low <= s.high && s.high - s.low > least_gap &&
                                     offsets[c][s.at - 1].first < s.high && offsets[c][s.at].first > s.low;
    if (!two_flat_layers(s, offsets[c]) && !parts_neighbourhood) continue;
    for (const auto& [offset, i] : offsets[c]) out.in_wall[i] = 1;
    ++out.cells;
  }
  return out;
}

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
      const detail::LeastVariancePlane plane =
          detail::FitLeastVariancePlane(positions, &nb[i * kPlaneNeighbours], kPlaneNeighbours, detail::UnitWeight);
      const double rms = plane.Rms(kPlaneNeighbours);
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

namespace {

// One sample per occupied cell of `sorted` and normal group (SimplifyDenseSamples' rule), over the
// samples i with take(i), appended to `out` in order of cell.
template <class Take>
void AppendCellMeans(const PointSet& points, const CellOrder& sorted, Take take, PointSet& out) {
  const bool lines = points.lines.size() == points.positions.size();
  struct Group {
    Eigen::Vector3d first_normal, position_sum, normal_sum;
    std::size_t count, first;
  };
  std::vector<Group> groups;
  for (std::size_t c = 0; c < sorted.Cells(); ++c) {
    groups.clear();
    for (std::size_t r = sorted.start[c]; r < sorted.start[c + 1]; ++r) {
      const std::size_t i = sorted.order[r];
      if (!take(i)) continue;
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
      out.positions.push_back(g.position_sum / static_cast<double>(g.count));
      const double length = g.normal_sum.norm();
      out.normals.push_back(length > 0 ? Eigen::Vector3d(g.normal_sum / length) : g.first_normal);
      if (lines) out.lines.push_back(points.lines[g.first]);
    }
  }
}

// A wide cell's samples lie this far off their own least-squares plane (RMS, units of the cell)
// or farther where they wrap round a thin part's rim: two creases in one cell, whose mean lies
// inside the part. One 90-degree crease through a cell's middle gives 0.10 (0.204 of an arm),
// a gently curved sheet less.
constexpr double kFoldCells = 0.15;
// ... and this many times the set's noise (ThinWallCells'), so that a noisy shell has none.
constexpr double kFoldNoises = 3.0;
constexpr std::size_t kLeastFoldSamples = 3;

// Per cell of `sorted`: whether its samples wrap round a rim (kFoldCells); wall cells never do.
std::vector<std::uint8_t> FoldedCells(const std::vector<Eigen::Vector3d>& positions, const CellOrder& sorted,
                                      double cell, const WallCells& walls) {
  std::vector<std::uint8_t> folded(sorted.Cells(), 0);
  const double least_rms = std::max(kFoldCells * cell, kFoldNoises * walls.noise);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, sorted.Cells(), 1024), [&](const auto& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      const std::size_t b = sorted.start[c], e = sorted.start[c + 1];
      if (e - b < kLeastFoldSamples || walls.in_wall[sorted.order[b]]) continue;
      const Eigen::Vector3d origin = positions[sorted.order[b]];  // precision, as in ThinWallCells
      Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
      detail::AddScatter(
          e - b, [&](std::size_t m) -> Eigen::Vector3d { return positions[sorted.order[b + m]] - origin; },
          detail::UnitWeight, scatter);
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> least(scatter, Eigen::EigenvaluesOnly);
      folded[c] = std::sqrt(std::max(0.0, least.eigenvalues()[0]) / static_cast<double>(e - b)) > least_rms ? 1 : 0;
    }
  });
  return folded;
}

}  // namespace

Simplification SimplifyDenseSamples(PointSet& points, double cell) {
  const std::size_t n = points.positions.size();
  Simplification out{n, n, cell};
  if (n < 2 || !(cell > 0)) return out;
  const CellOrder sorted = SortIntoCells(points.positions, cell);
  if (2 * sorted.Cells() > n) return out;  // not denser than the grid: leave the set as it was
  PointSet merged;
  merged.has_normals = points.has_normals;
  merged.positions.reserve(sorted.Cells());
  merged.normals.reserve(sorted.Cells());
  AppendCellMeans(
      points, sorted, [](std::size_t) { return true; }, merged);
  out.after = merged.positions.size();
  points = std::move(merged);
  return out;
}

Simplification SimplifyBarePositions(PointSet& points, double voxel) {
  points.normals.assign(points.positions.size(), Eigen::Vector3d::UnitZ());
  const Simplification half = SimplifyDenseSamples(points, 0.5 * voxel);
  if (half.Applied() || points.positions.size() < 2 || !(voxel > 0)) return half;
  const double wide = kDenseCellVoxels * voxel;
  const CellOrder sorted = SortIntoCells(points.positions, wide);
  if (2 * sorted.Cells() > points.positions.size()) return Simplification{half.before, half.after, wide};  // as it was
  // A cell holding a wall's two sides keeps every sample as it is: averaged, even per side, its
  // samples would be spaced as the wall is thick, and the orientation's nearest neighbours would
  // cross it. A cell wrapping round a rim is averaged in half-voxel cells: its one mean would lie
  // inside the part and bridge its sides. The rest are averaged per cell.
  const WallCells walls = ThinWallCells(points.positions, sorted, wide);
  const std::vector<std::uint8_t> folded = FoldedCells(points.positions, sorted, wide, walls);
  std::vector<std::uint8_t> in_fold(points.positions.size(), 0);
  std::size_t folds = 0;
  for (std::size_t c = 0; c < sorted.Cells(); ++c) {
    if (!folded[c]) continue;
    ++folds;
    for (std::size_t r = sorted.start[c]; r < sorted.start[c + 1]; ++r) in_fold[sorted.order[r]] = 1;
  }
  // The samples i with mask[i] set, as they are, appended to `to`.
  const bool lines = points.lines.size() == points.positions.size();
  const auto append_where = [&](const std::vector<std::uint8_t>& mask, PointSet& to) {
    for (std::size_t i = 0; i < points.positions.size(); ++i) {
      if (!mask[i]) continue;
      to.positions.push_back(points.positions[i]);
      to.normals.push_back(points.normals[i]);
      if (lines) to.lines.push_back(points.lines[i]);
    }
  };
  PointSet thinned;
  thinned.has_normals = points.has_normals;
  AppendCellMeans(
      points, sorted, [&](std::size_t i) { return !walls.in_wall[i] && !in_fold[i]; }, thinned);
  if (folds > 0) {
    PointSet fold;
    append_where(in_fold, fold);
    AppendCellMeans(
        fold, SortIntoCells(fold.positions, 0.5 * voxel), [](std::size_t) { return true; }, thinned);
  }
  append_where(walls.in_wall, thinned);
  points = std::move(thinned);
  Simplification out{half.before, points.positions.size(), wide};
  out.wall_cells = walls.cells;
  out.fold_cells = folds;
  return out;
}

WindingOutliers FindWindingOutliers(const std::vector<Eigen::Vector3d>& positions,
                                    const std::vector<Eigen::Vector3d>& normals, double min_jump) {
  constexpr double kSureOutlierJump = 0.0;
  constexpr double kLeastOthersJump = 0.2;
  constexpr std::size_t kOwnSideNeighbours = 64;
  constexpr double kSharesNormalCos = 0.8;  // n . n_j: a neighbour on the sample's own side
  constexpr double kPlaneOffset = 0.2;      // x the 16th neighbour's distance
  WindingOutliers out;
  const std::size_t n = positions.size();
  constexpr std::size_t kNeighbours = 16;
  if (n <= kNeighbours || normals.size() != n) return out;
  const SampleProbes probes(positions, normals);
  std::vector<double> jump = probes.Jumps(normals);
  // The others' share of sample i's jump, J - 2 x its own disc (1, no test, where no probe stands).
  const auto others = [&](std::size_t i) {
    const double d = probes.offsets()[i];
    return d > 0 ? jump[i] - 2.0 * SampleProbes::OwnDisc(probes.areas()[i], d) : 1.0;
  };
  const detail::PointCloud cloud{&positions};
  const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 64), [&](const auto& r) {
    std::array<std::size_t, kNeighbours + 1> idx{};
    std::array<double, kNeighbours + 1> d2{};
    std::array<std::size_t, kOwnSideNeighbours + 1> wide{};
    std::array<double, kOwnSideNeighbours + 1> wide_d2{};
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const Eigen::Vector3d& p = positions[i];
      const Eigen::Vector3d& nrm = normals[i];
      if (jump[i] < kSureOutlierJump || !(jump[i] < min_jump || others(i) < kLeastOthersJump)) continue;
      const std::size_t got = tree.knnSearch(p.data(), kNeighbours + 1, idx.data(), d2.data());
      if (!(jump[i] < min_jump)) {
        // A stray point facing a surface across a narrow gap: that surface, in front of it, holds
        // its probes within 0.4 of the gap, where its own disc makes most of J (CGAL's
        // pinion_small with a point moved 8 voxels out between two teeth, robustness.py seed 9:
        // J 0.58, the others' share 0.11), and its own side's samples lie behind it rather than
        // beside it (there: 4.6 spacings behind, the nearest straight behind). True samples with
        // a share that low lie beside their own side's (CGAL's dino, clean: share 0.19 and -0.03,
        // the nearest facing their way 3 spacings aside and 0.3 behind or 0.2 in front).
        const std::span near(idx.data(), got);
        const auto opposite = std::ranges::find_if(near, [&](std::size_t j) { return normals[j].dot(nrm) < -0.5; });
        if (opposite == near.end() || !((positions[*opposite] - p).dot(nrm) > 0)) continue;
        const std::span own_side(wide.data(),
                                 tree.knnSearch(p.data(), kOwnSideNeighbours + 1, wide.data(), wide_d2.data()));
        const auto own = std::ranges::find_if(
            own_side, [&](std::size_t j) { return j != i && normals[j].dot(nrm) >= kSharesNormalCos; });
        if (own == own_side.end()) continue;
        const Eigen::Vector3d behind = p - positions[*own];
        const double along = behind.dot(nrm);
        if (!(along > (behind - along * nrm).norm())) continue;
        jump[i] = std::max(others(i), kSureOutlierJump);
      }
      // Between the two: next to a sharp edge or a fin the jump of a true sample is low too, but
      // it lies on the plane of the neighbours that share its normal (fandisk: offsets below
      // 0.02 x the 16th neighbour's distance); an outlier does not, or has no such neighbours.
      Eigen::Vector3d centre = Eigen::Vector3d::Zero(), mean_normal = Eigen::Vector3d::Zero();
      int agree = 0;
      for (std::size_t m = 0; m < got; ++m) {
        if (idx[m] == i || normals[idx[m]].dot(nrm) < kSharesNormalCos) continue;
        centre += positions[idx[m]];
        mean_normal += normals[idx[m]];
        ++agree;
      }
      if (agree < 2) continue;  // no neighbour shares its normal: an outlier
      centre /= agree;
      const Eigen::Vector3d plane_normal = mean_normal.normalized();
      double noise2 = 0;  // the agreeing neighbours' own mean square offset: noise widens the test
      for (std::size_t m = 0; m < got; ++m) {
        if (idx[m] == i || normals[idx[m]].dot(nrm) < kSharesNormalCos) continue;
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
constexpr std::size_t kMinNeighbours = 8;  // MeasurePositionNoise's and SmoothNoisyPositions' least `neighbours`
constexpr double kShapeGrowth2 = 4.0;      // the squared growth of a shape's residual, 16 -> 48 neighbours
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
// bounds each move, and no neighbourhood holds more than the nearest `most`. A sample whose
// smallest neighbourhood's offsets scatter more than `scatter` (RMS about their mean; infinity:
// never) stays. Returns the samples that stayed so.
std::size_t BisectorPass(std::vector<Eigen::Vector3d>& positions, const std::vector<Eigen::Vector3d>& normals,
                         const detail::KdTree& tree, double noise, double cap, std::size_t most, double scatter) {
  const std::size_t n = positions.size();
  std::vector<double> move(n, std::numeric_limits<double>::quiet_NaN());
  std::atomic<std::size_t> stayed{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 64), [&](const auto& r) {
    std::array<std::size_t, kBisectorMaxNeighbours + 1> idx{};
    std::array<double, kBisectorMaxNeighbours + 1> d2{};
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      const Eigen::Vector3d& p = positions[i];
      const Eigen::Vector3d& nrm = normals[i];
      const std::size_t got = tree.knnSearch(p.data(), std::min(idx.size(), most + 1), idx.data(), d2.data());
      double sum = 0.0, sum2 = 0.0;
      int used = 0;
      double lo = -std::numeric_limits<double>::infinity(), hi = std::numeric_limits<double>::infinity();
      double chosen = std::numeric_limits<double>::quiet_NaN();
      std::size_t test_at = kBisectorMinNeighbours;  // idx[0..test_at]: itself and its nearest 16, 32, 64
      for (std::size_t m = 0; m < got; ++m) {
        const std::size_t j = idx[m];
        const double c = normals[j].dot(nrm);
        if (j != i && c >= kBisectorCos) {
          const double offset = (nrm + normals[j]).dot(positions[j] - p) / (1.0 + c);
          sum += offset;
          sum2 += offset * offset;
          ++used;
        }
        if (m != test_at && m + 1 != got) continue;
        test_at *= 2;
        if (used < 2) continue;
        // Noise alone scatters the offsets by about the residual; fitted lines that do not follow
        // the shape scatter them more, and their mean is not the surface.
        if (std::isnan(chosen) && sum2 - sum * sum / used > scatter * scatter * (used - 1)) {
          stayed.fetch_add(1, std::memory_order_relaxed);
          break;
        }
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
  return stayed.load();
}

}  // namespace

NoiseSmoothing MeasurePositionNoise(const std::vector<Eigen::Vector3d>& positions,
                                    const std::vector<Eigen::Vector3d>& normals, std::size_t neighbours) {
  if (positions.size() <= neighbours || normals.size() != positions.size() || neighbours < kMinNeighbours) return {};
  const detail::PointCloud cloud{&positions};
  const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  return MeasureNoise(positions, normals, tree, neighbours);
}

NoiseSmoothing SmoothNoisyPositions(std::vector<Eigen::Vector3d>& positions,
                                    const std::vector<Eigen::Vector3d>& normals, std::size_t neighbours,
                                    double threshold, int passes, int fitted_neighbours, double scatter) {
  const std::size_t n = positions.size();
  if (n <= neighbours || normals.size() != n || neighbours < kMinNeighbours) return {};
  const detail::PointCloud cloud{&positions};
  // The given positions: the measure's, and the first pass's of every move (each starts from them).
  const detail::KdTree given(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  NoiseSmoothing out = MeasureNoise(positions, normals, given, neighbours);
  if (!(out.noise > threshold)) return out;
  const std::vector<Eigen::Vector3d> before = positions;
  // `passes` Jacobi passes from `before`, each indexing the positions the previous one left; the
  // RMS |move| over all samples.
  const auto move = [&](std::size_t most, double spread) {
    positions = before;
    for (int pass = 0; pass < passes; ++pass) {
      std::optional<detail::KdTree> moved;
      if (pass > 0) moved.emplace(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
      // A move beyond kMaxMoveNoise x the residual is the shape (a detail finer than the
      // neighbours), not noise.
      const std::size_t stayed = BisectorPass(positions, normals, pass == 0 ? given : *moved, out.residual,
                                              kMaxMoveNoise * out.residual, most, spread);
      if (pass == 0) out.scattered = stayed;
    }
    double total2 = 0.0;
    for (std::size_t i = 0; i < n; ++i) total2 += (positions[i] - before[i]).squaredNorm();
    return std::sqrt(total2 / static_cast<double>(n));
  };
  out.rms_move = move(kBisectorMaxNeighbours, std::numeric_limits<double>::infinity());
  out.passes = std::max(passes, 0);
  out.widest = kBisectorMaxNeighbours;
  if (fitted_neighbours > 0) {
    // The moves estimate minus each sample's noise, so their RMS stays near the noise (0.9-1.2 x on
    // the bare noisy sets the moves improve). Moves well beyond it follow lines that the fit drew
    // across the shape: bare samples of a part whose creases and walls are as fine as the
    // neighbourhoods (the pinion, rotor, spool, couplingdown, CGAL's oblong and turbine: 1.4-1.9 x,
    // and the samples end farther from the surface than they started). Given normals carry shape
    // the positions do not, and their moves help up to 1.36 x (spool, 0.5 voxel, exact normals).
    if (out.rms_move > kMoveDiscrepancy * out.noise) {
      positions = before;
      out.withheld = true;
      return out;
    }
    // The fit widened only as far as the noise needed (EstimateNormalLines: 18 neighbours, more
    // while the lines stay rough), and the moves need no wider: beyond it the intervals, as wide
    // as the first residual in every pass, let detail pass for noise and round it off (CGAL's
    // bear, 0.3 voxel, bare: band mean 0.153 -> 0.140 voxel). Decided on the full move above:
    // narrower moves stay short enough to pass where the lines cross the shape (couplingdown,
    // 0.5 voxel, bare: 0.324 -> 0.465 voxel if the narrower moves were the ones asked).
    std::size_t most = kBisectorMaxNeighbours;
    while (most > kBisectorMinNeighbours && most > static_cast<std::size_t>(fitted_neighbours)) most /= 2;
    // And only where the lines follow the shape: the hand's fingers and the cow's legs, a few
    // spacings across, turn the 18-neighbour lines 10-40 degrees off, and the offsets along them
    // scatter; moved anyway, such samples end farther from the surface (CGAL's hand, 0.3 voxel,
    // bare: band mean 0.235 -> 0.189 voxel; docs/field-methods.md § Bare noisy samples: a sample
    // moves only where its neighbours' offsets agree).
    out.rms_move = move(most, scatter * out.residual);
    out.widest = most;
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
  return out;
}

}  // namespace palpa::field
