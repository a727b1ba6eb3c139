// Whether a field touches its grid's boundary (issue 19): nodes on the grid's six faces where
// φ < 0. palpad extends the boundary value outward (sampler::TrilinearSampler), so such a face is
// a wall, not free space; `palpa build` warns about it, since the object is cut off there.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

namespace palpa::cli {

/// Nodes on the grid's faces with φ < 0. `phi(i, j, k)`: a node's Q16.16 value; `dims`: nodes
/// per axis.
template <typename Dim, typename NodeQ16>
std::size_t NegativeFaceNodes(const NodeQ16& phi, const std::array<Dim, 3>& dims) {
  const auto nx = static_cast<std::size_t>(dims[0]), ny = static_cast<std::size_t>(dims[1]),
             nz = static_cast<std::size_t>(dims[2]);
  std::size_t count = 0;
  for (std::size_t i = 0; i < nx; ++i)
    for (std::size_t j = 0; j < ny; ++j) {
      const bool face_ij = i == 0 || i + 1 == nx || j == 0 || j + 1 == ny;
      if (face_ij) {
        for (std::size_t k = 0; k < nz; ++k)
          if (phi(i, j, k) < 0) ++count;
      } else if (nz > 0) {
        if (phi(i, j, 0) < 0) ++count;
        if (nz > 1 && phi(i, j, nz - 1) < 0) ++count;
      }
    }
  return count;
}

/// As above over a dense field: `phi` holds Q16.16 node values in C order (x slowest).
template <typename Dim>
std::size_t NegativeFaceNodes(std::span<const std::int32_t> phi, const std::array<Dim, 3>& dims) {
  const auto ny = static_cast<std::size_t>(dims[1]), nz = static_cast<std::size_t>(dims[2]);
  return NegativeFaceNodes([&](std::size_t i, std::size_t j, std::size_t k) { return phi[(i * ny + j) * nz + k]; },
                           dims);
}

}  // namespace palpa::cli
