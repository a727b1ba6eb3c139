#include "palpa/field/coverage.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include "palpa/field/hermite_field.h"
#include "point_cloud.h"

namespace palpa::field {
namespace {

using V3 = Eigen::Vector3d;

constexpr double kCoverSpacings = 3.0;

struct Count {
  std::size_t crossings = 0;
  std::size_t uncovered = 0;
};

}  // namespace

Coverage MeasureCoverage(const SparseField& field, const std::vector<V3>& samples) {
  Coverage out;
  const GridSpec& grid = field.grid();
  const double h = grid.voxel_m;
  if (samples.empty() || !(h > 0.0)) return out;
  const detail::PointCloud cloud{&samples};
  const detail::KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  out.min_distance_m = std::max(kCoverSpacings * detail::Median(SampleSpacing(samples, 1)), h);
  constexpr int kB = SparseField::kBrick;
  const std::array<int, 3>& bd = field.brick_dims();
  const std::size_t bricks =
      static_cast<std::size_t>(bd[0]) * static_cast<std::size_t>(bd[1]) * static_cast<std::size_t>(bd[2]);
  const Count total = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, bricks, 16), Count{},
      [&](const auto& r, Count c) {
        // The samples that may lie within min_distance of a crossing of the brick: every crossing
        // lies in the box of nodes base .. base + kB (edges leave the brick by one step), so within
        // its half diagonal of the box's centre. Gathered at the brick's first crossing; each
        // crossing then asks them, not the tree (the same test: AnyWithin on nanoflann's distance).
        std::vector<std::pair<std::size_t, double>> candidates;  // (sample, squared distance)
        bool gathered = false;
        V3 centre = V3::Zero();
        const double reach = out.min_distance_m + 0.5 * kB * std::sqrt(3.0) * h;
        // One crossing test: the edge from node (i, j, k), phi `here`, one step along axis `s`.
        const auto edge = [&](int i, int j, int k, double here, int s, double there) {
          if ((here <= 0.0) == (there <= 0.0)) return;
          ++c.crossings;
          const double t = here / (here - there);  // the zero along the edge, in [0, 1]
          V3 p = grid.origin_m + h * V3(i, j, k);
          p[s] += h * t;
          if (!gathered) {
            const double radius = reach * (1.0 + 1e-9);
            tree.radiusSearch(centre.data(), radius * radius, candidates, nanoflann::SearchParams(32, 0.0f, false));
            gathered = true;
          }
          detail::AnyWithin near(out.min_distance_m);
          // The distance as the tree's own searches sum it (nanoflann's L2_Simple_Adaptor).
          for (const auto& match : candidates)
            if (!near.addPoint(tree.distance.evalMetric(p.data(), static_cast<unsigned>(match.first), 3), match.first))
              break;
          if (!near.found()) ++c.uncovered;
        };
        for (std::size_t b = r.begin(); b != r.end(); ++b) {
          const std::array<int, 3> bc = field.BrickCoords(b);
          const std::array<int, 3> base{bc[0] * kB, bc[1] * kB, bc[2] * kB};
          gathered = false;
          centre = grid.origin_m + h * (V3(base[0], base[1], base[2]) + V3::Constant(0.5 * kB));
          const float* values = field.BrickValues(b);
          if (values == nullptr) {
            // Uniform: no edge crosses inside it; across a face, only into a brick that is not
            // uniform with the same sign.
            for (int s = 0; s < 3; ++s) {
              std::array<int, 3> next = bc;
              ++next[static_cast<std::size_t>(s)];
              if (next[static_cast<std::size_t>(s)] >= bd[static_cast<std::size_t>(s)]) continue;
              if (field.Slot(field.BrickIndex(next[0], next[1], next[2])) == field.Slot(b)) continue;
              const double here = field.Slot(b) == SparseField::kUniformInside ? -grid.band_voxels : grid.band_voxels;
              const int u = (s + 1) % 3, v = (s + 2) % 3;
              for (int x = 0; x < kB; ++x)
                for (int y = 0; y < kB; ++y) {
                  std::array<int, 3> node = base;
                  node[static_cast<std::size_t>(s)] += kB - 1;
                  node[static_cast<std::size_t>(u)] += x;
                  node[static_cast<std::size_t>(v)] += y;
                  std::array<int, 3> far = node;
                  ++far[static_cast<std::size_t>(s)];
                  if (far[0] >= grid.dims[0] || far[1] >= grid.dims[1] || far[2] >= grid.dims[2]) continue;
                  edge(node[0], node[1], node[2], here, s, field.Value(far[0], far[1], far[2]));
                }
            }
            continue;
          }
          // Each node's edges to its +i, +j, +k neighbours in the grid; within the brick straight
          // from its values, across its upper faces through Value.
          const int na = std::min(kB, grid.dims[0] - base[0]), ne = std::min(kB, grid.dims[1] - base[1]),
                    nf = std::min(kB, grid.dims[2] - base[2]);
          for (int a = 0; a < na; ++a)
            for (int e = 0; e < ne; ++e)
              for (int f = 0; f < nf; ++f) {
                const int i = base[0] + a, j = base[1] + e, k = base[2] + f;
                const int at = (a * kB + e) * kB + f;
                const double here = values[at];
                if (i + 1 < grid.dims[0])
                  edge(i, j, k, here, 0, a + 1 < kB ? values[at + kB * kB] : field.Value(i + 1, j, k));
                if (j + 1 < grid.dims[1])
                  edge(i, j, k, here, 1, e + 1 < kB ? values[at + kB] : field.Value(i, j + 1, k));
                if (k + 1 < grid.dims[2])
                  edge(i, j, k, here, 2, f + 1 < kB ? values[at + 1] : field.Value(i, j, k + 1));
              }
        }
        return c;
      },
      [](Count x, const Count& y) {
        x.crossings += y.crossings;
        x.uncovered += y.uncovered;
        return x;
      });
  out.total_area_m2 = static_cast<double>(total.crossings) * h * h / 1.5;
  out.uncovered_area_m2 = static_cast<double>(total.uncovered) * h * h / 1.5;
  return out;
}

}  // namespace palpa::field
