// Helpers for the tools tests: run the `palpa` binary, temporary directories, and closed meshes
// whose geometry is known exactly (boxes, icospheres).
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <utility>

#include <gtest/gtest.h>

#include "palpa/mesh/triangle_mesh.h"
#include "process.h"

namespace palpa::tools_test {

namespace fs = std::filesystem;

inline fs::path DataFile(const std::string& name) { return fs::path(PALPA_DATA_DIR) / name; }

using test_support::Outcome;
using test_support::TempDirTest;

/// Runs `palpa ARGS` through the shell and captures its output and exit code.
inline Outcome Palpa(const std::string& args) { return test_support::Run(std::string(PALPA_BIN) + " " + args); }

inline std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// Axis-aligned box [lo, hi] as 12 outward (counter-clockwise seen from outside) triangles.
inline mesh::TriangleMesh Box(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  mesh::TriangleMesh m;
  for (int c = 0; c < 8; ++c)
    m.vertices.emplace_back((c & 1) ? hi.x() : lo.x(), (c & 2) ? hi.y() : lo.y(), (c & 4) ? hi.z() : lo.z());
  // Quads (outward winding), each split into two triangles.
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.faces.push_back({q[0], q[1], q[2]});
    m.faces.push_back({q[0], q[2], q[3]});
  }
  return m;
}

/// Icosahedron subdivided `levels` times, vertices on the sphere of radius `r` about `centre`,
/// outward winding. Faces: 20·4^levels.
inline mesh::TriangleMesh Icosphere(int levels, double r, const Eigen::Vector3d& centre = Eigen::Vector3d::Zero()) {
  mesh::TriangleMesh m;
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  const double raw[12][3] = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                             {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (const auto& v : raw) m.vertices.push_back(Eigen::Vector3d(v[0], v[1], v[2]).normalized());
  m.faces = {{0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
             {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
             {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int level = 0; level < levels; ++level) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      if (auto it = mid.find(key); it != mid.end()) return it->second;
      m.vertices.push_back(
          (m.vertices[static_cast<std::size_t>(a)] + m.vertices[static_cast<std::size_t>(b)]).normalized());
      const int id = static_cast<int>(m.vertices.size()) - 1;
      mid.emplace(key, id);
      return id;
    };
    std::vector<std::array<int, 3>> next;
    for (const auto& f : m.faces) {
      const int a = midpoint(f[0], f[1]);
      const int b = midpoint(f[1], f[2]);
      const int c = midpoint(f[2], f[0]);
      next.push_back({f[0], a, c});
      next.push_back({f[1], b, a});
      next.push_back({f[2], c, b});
      next.push_back({a, b, c});
    }
    m.faces = std::move(next);
  }
  for (auto& v : m.vertices) v = centre + r * v;
  return m;
}

/// The mesh as an OFF file's text.
inline std::string ToOff(const mesh::TriangleMesh& m) {
  std::string s = "OFF\n" + std::to_string(m.vertices.size()) + " " + std::to_string(m.faces.size()) + " 0\n";
  char line[128];
  for (const auto& v : m.vertices) {
    std::snprintf(line, sizeof line, "%.17g %.17g %.17g\n", v.x(), v.y(), v.z());
    s += line;
  }
  for (const auto& f : m.faces)
    s += "3 " + std::to_string(f[0]) + " " + std::to_string(f[1]) + " " + std::to_string(f[2]) + "\n";
  return s;
}

}  // namespace palpa::tools_test
