#include "palpa/field/edt_field.h"

#include <algorithm>
#include <array>
#include <cmath>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

namespace palpa::field {
namespace {

// Per-thread scratch for one line: the envelope's parabola sites v, boundaries z, and a copy of
// the input line.
struct LineScratch {
  std::vector<int> v;
  std::vector<float> z;
  std::vector<float> line;
};

// 1-D squared distance transform of the `n` values at data[0], data[stride], ... (F&H alg. 1).
// Sites with f >= infinity are skipped: they can never be the minimum below the cap.
void Transform1d(float* data, std::size_t stride, int n, float infinity, LineScratch& s) {
  s.line.resize(static_cast<std::size_t>(n));
  s.v.resize(static_cast<std::size_t>(n));
  s.z.resize(static_cast<std::size_t>(n) + 1);
  for (int q = 0; q < n; ++q) s.line[static_cast<std::size_t>(q)] = data[static_cast<std::size_t>(q) * stride];
  const float* f = s.line.data();
  int k = -1;
  for (int q = 0; q < n; ++q) {
    if (!(f[q] < infinity)) continue;
    const auto fq = static_cast<double>(f[q]);
    double boundary = -HUGE_VAL;
    while (k >= 0) {
      const int p = s.v[static_cast<std::size_t>(k)];
      // Intersection of the parabolas rooted at p and q.
      boundary = ((fq + double(q) * q) - (static_cast<double>(f[p]) + double(p) * p)) / (2.0 * (q - p));
      if (boundary > static_cast<double>(s.z[static_cast<std::size_t>(k)])) break;
      --k;
    }
    ++k;
    s.v[static_cast<std::size_t>(k)] = q;
    s.z[static_cast<std::size_t>(k)] = k == 0 ? -HUGE_VALF : static_cast<float>(boundary);
    s.z[static_cast<std::size_t>(k) + 1] = HUGE_VALF;
  }
  if (k < 0) return;  // no finite site: the line stays at infinity
  int j = 0;
  for (int q = 0; q < n; ++q) {
    while (static_cast<double>(s.z[static_cast<std::size_t>(j) + 1]) < q) ++j;
    const int p = s.v[static_cast<std::size_t>(j)];
    const double d = double(q - p) * (q - p) + static_cast<double>(f[p]);
    data[static_cast<std::size_t>(q) * stride] = static_cast<float>(std::min(d, static_cast<double>(infinity)));
  }
}

}  // namespace

void SquaredEdt(const std::array<int, 3>& dims, std::vector<float>& f, float infinity) {
  const auto nx = static_cast<std::size_t>(dims[0]);
  const auto ny = static_cast<std::size_t>(dims[1]);
  const auto nz = static_cast<std::size_t>(dims[2]);
  tbb::enumerable_thread_specific<LineScratch> scratch;
  // k lines (contiguous), then j lines, then i lines.
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nx * ny), [&](const tbb::blocked_range<std::size_t>& r) {
    LineScratch& s = scratch.local();
    for (std::size_t row = r.begin(); row != r.end(); ++row) Transform1d(f.data() + row * nz, 1, dims[2], infinity, s);
  });
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nx * nz), [&](const tbb::blocked_range<std::size_t>& r) {
    LineScratch& s = scratch.local();
    for (std::size_t line = r.begin(); line != r.end(); ++line) {
      const std::size_t i = line / nz, k = line % nz;
      Transform1d(f.data() + i * ny * nz + k, nz, dims[1], infinity, s);
    }
  });
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, ny * nz), [&](const tbb::blocked_range<std::size_t>& r) {
    LineScratch& s = scratch.local();
    for (std::size_t line = r.begin(); line != r.end(); ++line)
      Transform1d(f.data() + line, ny * nz, dims[0], infinity, s);
  });
}

std::vector<float> SignedEdtField(const GridSpec& grid, const std::vector<std::uint8_t>& indicator) {
  const std::size_t n = grid.NodeCount();
  if (n == 0 || indicator.size() != n) return {};
  const int band = std::clamp(grid.band_voxels, 1, 64);
  // Distances beyond band + 1/2 all clamp alike, so the transform can stop there.
  const float cap = static_cast<float>((band + 1) * (band + 1));
  const int nx = grid.dims[0], ny = grid.dims[1], nz = grid.dims[2];
  const auto in_s = [&](std::size_t x, int i, int j, int k) {
    return indicator[x] != 0 && i > 0 && j > 0 && k > 0 && i < nx - 1 && j < ny - 1 && k < nz - 1;
  };
  std::vector<float> to_inside(n), to_outside(n);
  tbb::parallel_for(0, nx, [&](int i) {
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < nz; ++k) {
        const std::size_t x = grid.Index(i, j, k);
        const bool s = in_s(x, i, j, k);
        to_inside[x] = s ? 0.0f : cap;
        to_outside[x] = s ? cap : 0.0f;
      }
  });
  SquaredEdt(grid.dims, to_inside, cap);
  SquaredEdt(grid.dims, to_outside, cap);
  const auto b = static_cast<float>(band);
  tbb::parallel_for(0, nx, [&](int i) {
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < nz; ++k) {
        const std::size_t x = grid.Index(i, j, k);
        const float phi = in_s(x, i, j, k) ? -(std::sqrt(to_outside[x]) - 0.5f) : std::sqrt(to_inside[x]) - 0.5f;
        to_inside[x] = std::clamp(phi, -b, b);
      }
  });
  return to_inside;
}

}  // namespace palpa::field
