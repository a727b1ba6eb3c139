#include "palpa/field/erosion_field.h"

#include <algorithm>
#include <array>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace palpa::field {
namespace {

using Dist = std::uint8_t;

// In-place 6-connected (city-block) distance transform of d, in node steps, saturating at `cap`
// (inputs are 0 on sources and cap elsewhere). The city-block metric is a sum over axes, so the
// 3-D transform is three 1-D min-plus passes, one per axis; the result equals the multi-source
// BFS distance, because a shortest lattice path to the nearest source cannot pass another source.
// Nodes outside the grid are ignored; ErosionField makes the grid faces outside nodes, which
// already dominate anything beyond them.
class CityBlock {
 public:
  explicit CityBlock(const std::array<int, 3>& dims)
      : nx_(static_cast<std::size_t>(dims[0])),
        ny_(static_cast<std::size_t>(dims[1])),
        nz_(static_cast<std::size_t>(dims[2])) {}

  void Run(Dist* d) const {
    PassK(d);
    PassJ(d);
    PassI(d);
  }

 private:
  // dst[k] = min(dst[k], src[k] + 1) over a contiguous row of nz nodes.
  void Relax(Dist* dst, const Dist* src) const {
    for (std::size_t k = 0; k < nz_; ++k) {
      dst[k] = std::min(dst[k], static_cast<Dist>(src[k] + 1));
    }
  }

  void PassK(Dist* d) const {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nx_ * ny_), [&](const tbb::blocked_range<std::size_t>& rows) {
      for (std::size_t r = rows.begin(); r != rows.end(); ++r) {
        Dist* row = d + r * nz_;
        for (std::size_t k = 1; k < nz_; ++k) {
          row[k] = std::min(row[k], static_cast<Dist>(row[k - 1] + 1));
        }
        for (std::size_t k = nz_ - 1; k-- > 0;) {
          row[k] = std::min(row[k], static_cast<Dist>(row[k + 1] + 1));
        }
      }
    });
  }

  void PassJ(Dist* d) const {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nx_), [&](const tbb::blocked_range<std::size_t>& planes) {
      for (std::size_t i = planes.begin(); i != planes.end(); ++i) {
        Dist* plane = d + i * ny_ * nz_;
        for (std::size_t j = 1; j < ny_; ++j) Relax(plane + j * nz_, plane + (j - 1) * nz_);
        for (std::size_t j = ny_ - 1; j-- > 0;) Relax(plane + j * nz_, plane + (j + 1) * nz_);
      }
    });
  }

  void PassI(Dist* d) const {
    const std::size_t stride = ny_ * nz_;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, ny_), [&](const tbb::blocked_range<std::size_t>& columns) {
      for (std::size_t j = columns.begin(); j != columns.end(); ++j) {
        Dist* line = d + j * nz_;
        for (std::size_t i = 1; i < nx_; ++i) Relax(line + i * stride, line + (i - 1) * stride);
        for (std::size_t i = nx_ - 1; i-- > 0;) Relax(line + i * stride, line + (i + 1) * stride);
      }
    });
  }

  std::size_t nx_, ny_, nz_;
};

// Applies f(index_begin, index_end) over [0, n) in parallel chunks.
template <class F>
void ForNodes(std::size_t n, F&& f) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, std::size_t{1} << 16),
                    [&](const tbb::blocked_range<std::size_t>& r) { f(r.begin(), r.end()); });
}

}  // namespace

DenseField ErosionField(const GridSpec& grid, const std::vector<std::uint8_t>& indicator) {
  DenseField field;
  field.grid = grid;
  const std::size_t n = grid.NodeCount();
  if (n == 0 || indicator.size() != n) return field;
  const int band = std::clamp(grid.band_voxels, 1, 64);
  const Dist cap = static_cast<Dist>(band + 1);  // distances beyond the band all clamp alike

  // S = indicator nodes, minus the outer grid faces (always outside).
  std::vector<std::uint8_t> in_s(n);
  ForNodes(n, [&](std::size_t b, std::size_t e) {
    for (std::size_t x = b; x < e; ++x) in_s[x] = indicator[x] != 0 ? 1 : 0;
  });
  const int nx = grid.dims[0];
  const int ny = grid.dims[1];
  const int nz = grid.dims[2];
  for (int i = 0; i < nx; ++i) {
    for (int j = 0; j < ny; ++j) {
      if (i == 0 || i == nx - 1 || j == 0 || j == ny - 1) {
        std::fill_n(in_s.begin() + static_cast<std::ptrdiff_t>(grid.Index(i, j, 0)), nz, 0);
      } else {
        in_s[grid.Index(i, j, 0)] = 0;
        in_s[grid.Index(i, j, nz - 1)] = 0;
      }
    }
  }

  field.phi_voxels.assign(n, 0.0f);
  std::vector<Dist> d(n);

  // Inside: d_out = distance to the nearest node not in S.
  ForNodes(n, [&](std::size_t b, std::size_t e) {
    for (std::size_t x = b; x < e; ++x) d[x] = in_s[x] ? cap : Dist{0};
  });
  CityBlock(grid.dims).Run(d.data());
  ForNodes(n, [&](std::size_t b, std::size_t e) {
    for (std::size_t x = b; x < e; ++x) {
      if (in_s[x]) field.phi_voxels[x] = -static_cast<float>(std::min(band, d[x] - 1));
    }
  });

  // Outside: d_in = distance to the nearest node of S.
  ForNodes(n, [&](std::size_t b, std::size_t e) {
    for (std::size_t x = b; x < e; ++x) d[x] = in_s[x] ? Dist{0} : cap;
  });
  CityBlock(grid.dims).Run(d.data());
  ForNodes(n, [&](std::size_t b, std::size_t e) {
    for (std::size_t x = b; x < e; ++x) {
      if (!in_s[x]) field.phi_voxels[x] = static_cast<float>(std::min<int>(band, d[x]));
    }
  });

  field.inside_nodes = static_cast<std::size_t>(std::count(in_s.begin(), in_s.end(), 1));
  return field;
}

}  // namespace palpa::field
