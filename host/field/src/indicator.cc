#include "palpa/field/indicator.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace palpa::field {
namespace {

// Nodes along i per task. Each task owns whole i-planes, so no two threads write the same bytes.
constexpr int kSlabPlanes = 4;

// First guess of the node range [lo, hi] whose coordinate origin + idx*h is within `half` of
// `centre`, clamped to [0, n - 1] (hi < lo when empty). It only needs to be within a node or so:
// callers trim it with the exact predicate. Truncating casts instead of floor/ceil, which are
// library calls on baseline x86-64 and dominated the run time.
inline void GuessRange(double centre_idx, double half_idx, int n, int& lo, int& hi) {
  const double a = std::clamp(centre_idx - half_idx, 0.0, static_cast<double>(n - 1));
  const double b = std::clamp(centre_idx + half_idx, -1.0, static_cast<double>(n - 1));
  lo = static_cast<int>(a);
  hi = b < 0.0 ? -1 : static_cast<int>(b);
}

struct Ball {
  Eigen::Vector3d centre;
  double radius_sq;
  int i_lo, i_hi;
};

// Fills the nodes of planes [i_begin, i_end) strictly inside `ball`. Every node is decided by the
// same predicate dx^2 + dy^2 + dz^2 < r^2, so each span is exactly the strict-inside set.
void RasteriseBall(const GridSpec& grid, const Ball& ball, int i_begin, int i_end, std::uint8_t* out) {
  const double h = grid.voxel_m;
  const double inv_h = 1.0 / h;
  const int ny = grid.dims[1];
  const int nz = grid.dims[2];
  const double r2 = ball.radius_sq;
  const double cy_idx = (ball.centre.y() - grid.origin_m.y()) * inv_h;
  const double cz_idx = (ball.centre.z() - grid.origin_m.z()) * inv_h;
  for (int i = std::max(i_begin, ball.i_lo); i < std::min(i_end, ball.i_hi + 1); ++i) {
    const double dx = grid.origin_m.x() + i * h - ball.centre.x();
    const double dx2 = dx * dx;
    if (!(dx2 < r2)) continue;
    const auto row_inside = [&](int j) {
      const double dy = grid.origin_m.y() + j * h - ball.centre.y();
      return dx2 + dy * dy < r2;
    };
    int j_lo = 0;
    int j_hi = -1;
    GuessRange(cy_idx, std::sqrt(r2 - dx2) * inv_h, ny, j_lo, j_hi);
    while (j_lo > 0 && row_inside(j_lo - 1)) --j_lo;
    while (j_hi < ny - 1 && row_inside(j_hi + 1)) ++j_hi;
    // The span moves little from row to row, so each row starts from the previous row's span and
    // the exact trims below (about two tests per end) replace a square root and a guess.
    int k_lo = 0;
    int k_hi = -1;
    bool have_span = false;
    for (int j = j_lo; j <= j_hi; ++j) {
      const double dy = grid.origin_m.y() + j * h - ball.centre.y();
      const double dxy2 = dx2 + dy * dy;
      if (!(dxy2 < r2)) {
        have_span = false;
        continue;
      }
      const auto inside = [&](int k) {
        const double dz = grid.origin_m.z() + k * h - ball.centre.z();
        return dxy2 + dz * dz < r2;
      };
      if (!have_span || k_lo > k_hi) {
        GuessRange(cz_idx, std::sqrt(r2 - dxy2) * inv_h, nz, k_lo, k_hi);
      }
      while (k_lo > 0 && inside(k_lo - 1)) --k_lo;
      while (k_lo <= k_hi && !inside(k_lo)) ++k_lo;
      while (k_hi < nz - 1 && inside(k_hi + 1)) ++k_hi;
      while (k_hi >= k_lo && !inside(k_hi)) --k_hi;
      have_span = k_lo <= k_hi;
      if (!have_span) continue;
      std::memset(out + grid.Index(i, j, k_lo), 1, static_cast<std::size_t>(k_hi - k_lo + 1));
    }
  }
}

}  // namespace

std::vector<std::uint8_t> Indicator(const GridSpec& grid, const Packing& packing) {
  std::vector<std::uint8_t> indicator(grid.NodeCount(), 0);
  const int nx = grid.dims[0];
  if (indicator.empty() || !(grid.voxel_m > 0.0)) return indicator;

  const std::size_t n_balls = std::min(packing.centres.size(), packing.radii.size());
  std::vector<Ball> balls;
  balls.reserve(n_balls);
  for (std::size_t b = 0; b < n_balls; ++b) {
    const double r = packing.radii[b];
    const Eigen::Vector3d& c = packing.centres[b];
    if (!(r > 0.0) || !std::isfinite(r) || !c.allFinite()) continue;
    // Planes possibly within r; one spare plane each side absorbs rounding (RasteriseBall tests
    // every plane exactly).
    Ball ball{c, r * r, 0, -1};
    GuessRange((c.x() - grid.origin_m.x()) / grid.voxel_m, r / grid.voxel_m + 1.0, nx, ball.i_lo, ball.i_hi);
    if (ball.i_lo <= ball.i_hi) balls.push_back(ball);
  }

  // Bucket balls by the slabs they cross, in ball order (the result does not depend on it).
  const int n_slabs = (nx + kSlabPlanes - 1) / kSlabPlanes;
  std::vector<std::vector<std::size_t>> buckets(static_cast<std::size_t>(n_slabs));
  for (std::size_t b = 0; b < balls.size(); ++b) {
    for (int s = balls[b].i_lo / kSlabPlanes; s <= balls[b].i_hi / kSlabPlanes; ++s) {
      buckets[static_cast<std::size_t>(s)].push_back(b);
    }
  }

  std::uint8_t* out = indicator.data();
  tbb::parallel_for(tbb::blocked_range<int>(0, n_slabs, 1), [&](const tbb::blocked_range<int>& range) {
    for (int s = range.begin(); s != range.end(); ++s) {
      const int i_begin = s * kSlabPlanes;
      const int i_end = std::min(nx, i_begin + kSlabPlanes);
      for (const std::size_t b : buckets[static_cast<std::size_t>(s)]) {
        RasteriseBall(grid, balls[b], i_begin, i_end, out);
      }
    }
  });
  return indicator;
}

}  // namespace palpa::field
