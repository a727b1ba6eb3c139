// Helpers shared by the palpa_field tests.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Core>

#include "palpa/field/point_io.h"
#include "palpa/mesh/sample.h"
#include "palpa/mesh/triangle_mesh.h"

namespace palpa::field::testing {

inline std::filesystem::path DataFile(std::string_view name) { return std::filesystem::path(PALPA_DATA_DIR) / name; }

// `count` area-uniform samples of the bundled closed mesh `file` with its exact face normals
// (mesh::SampleSurface, model units); a failure to read or sample fails the calling test.
inline PointSet SampledMesh(const char* file, std::size_t count, std::uint64_t seed = 1) {
  auto m = mesh::ReadClosedMesh(DataFile(file));
  EXPECT_TRUE(m.has_value()) << m.error().message;
  auto points = mesh::SampleSurface(*m, count, seed, file);
  EXPECT_TRUE(points.has_value()) << points.error().message;
  return *points;
}

// Point i of n on the unit sphere (Fibonacci lattice: near-uniform); it is also the outward normal.
inline Eigen::Vector3d FibonacciPoint(std::size_t i, std::size_t n) {
  const double golden = std::numbers::pi * (3.0 - std::sqrt(5.0));
  const double z = 1.0 - 2.0 * (static_cast<double>(i) + 0.5) / static_cast<double>(n);
  const double rho = std::sqrt(1.0 - z * z);
  const double t = golden * static_cast<double>(i);
  return {rho * std::cos(t), rho * std::sin(t), z};
}

// `n` area-uniform samples of a torus round the z axis (ring radius `ring`, tube radius `tube`) with
// their exact outward normals, drawn with std::mt19937_64(seed): u round the ring, v round the
// tube, a draw kept with probability (ring + tube cos v) / (ring + tube).
inline PointSet TorusSamples(double ring, double tube, std::size_t n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  PointSet out;
  while (out.positions.size() < n) {
    const double u = 2 * std::numbers::pi * unit(rng), v = 2 * std::numbers::pi * unit(rng);
    if (unit(rng) * (ring + tube) > ring + tube * std::cos(v)) continue;  // area-uniform
    const Eigen::Vector3d normal(std::cos(v) * std::cos(u), std::cos(v) * std::sin(u), std::sin(v));
    out.positions.push_back(Eigen::Vector3d(ring * std::cos(u), ring * std::sin(u), 0) + tube * normal);
    out.normals.push_back(normal);
  }
  return out;
}

// A file under the test temp dir that is removed when the object goes out of scope.
class TempFile {
 public:
  TempFile(std::string_view name, std::string_view contents)
      : path_(std::filesystem::path(::testing::TempDir()) / name) {
    std::ofstream out(path_, std::ios::binary);
    out << contents;
  }
  ~TempFile() {
    std::error_code ec;
    std::filesystem::remove(path_, ec);
  }
  TempFile(const TempFile&) = delete;
  TempFile& operator=(const TempFile&) = delete;
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

}  // namespace palpa::field::testing
