#include "palpa/mesh/iso_surface.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#include <dlfcn.h>
#include <fmt/core.h>
#include <malloc.h>
#include <unistd.h>

#include <filesystem>
#include <functional>
#include <mutex>
#include <span>
#include <string>

#include "iso_surface_internal.h"
#include "palpa/mesh/field_file.h"

namespace palpa::mesh {
namespace {

// The cell holding `p` (clamped into the grid) and the fractions inside it.
struct Cell {
  std::array<int, 3> base{};
  Eigen::Vector3d t;
  std::array<double, 8> c{};  // c[(di << 2) | (dj << 1) | dk]
};

Cell Locate(const blob::FieldView& f, const Eigen::Vector3d& p) {
  Cell cell;
  for (int a = 0; a < 3; ++a) {
    const auto s = static_cast<std::size_t>(a);
    const double hi = f.dims[s] - 1;
    const double x = std::clamp(p[a], 0.0, hi);
    cell.base[s] = std::min(static_cast<int>(std::floor(x)), f.dims[s] - 2);
    cell.t[a] = x - cell.base[s];
  }
  for (int corner = 0; corner < 8; ++corner)
    cell.c[static_cast<std::size_t>(corner)] =
        PhiVoxels(f, cell.base[0] + (corner >> 2), cell.base[1] + ((corner >> 1) & 1), cell.base[2] + (corner & 1));
  return cell;
}

void Append(std::vector<std::byte>& out, const void* data, std::size_t size) {
  const auto* b = static_cast<const std::byte*>(data);
  out.insert(out.end(), b, b + size);
}

}  // namespace

double TrilinearPhi(const blob::FieldView& field, const Eigen::Vector3d& index_point) {
  const Cell cl = Locate(field, index_point);
  const double u = cl.t.x();
  const double v = cl.t.y();
  const double w = cl.t.z();
  const auto& c = cl.c;
  return (1 - u) * ((1 - v) * ((1 - w) * c[0] + w * c[1]) + v * ((1 - w) * c[2] + w * c[3])) +
         u * ((1 - v) * ((1 - w) * c[4] + w * c[5]) + v * ((1 - w) * c[6] + w * c[7]));
}

Eigen::Vector3d TrilinearGradient(const blob::FieldView& field, const Eigen::Vector3d& index_point) {
  const Cell cl = Locate(field, index_point);
  const double u = cl.t.x();
  const double v = cl.t.y();
  const double w = cl.t.z();
  const auto& c = cl.c;
  const double gx = (1 - v) * (1 - w) * (c[4] - c[0]) + (1 - v) * w * (c[5] - c[1]) + v * (1 - w) * (c[6] - c[2]) +
                    v * w * (c[7] - c[3]);
  const double gy = (1 - u) * (1 - w) * (c[2] - c[0]) + (1 - u) * w * (c[3] - c[1]) + u * (1 - w) * (c[6] - c[4]) +
                    u * w * (c[7] - c[5]);
  const double gz = (1 - u) * (1 - v) * (c[1] - c[0]) + (1 - u) * v * (c[3] - c[2]) + u * (1 - v) * (c[5] - c[4]) +
                    u * v * (c[7] - c[6]);
  return {gx, gy, gz};
}

namespace internal {

std::expected<void, std::string> VolumeToMesh(const blob::FieldView& field, std::vector<Eigen::Vector3d>& points,
                                              std::vector<std::array<int, 3>>& triangles,
                                              std::vector<std::array<int, 4>>& quads) {
  static std::once_flag once;
  static VolumeToMeshFn entry = nullptr;
  static std::string failure;
  std::call_once(once, [] {
    // Beside the executable (build tree), where the package installs it (relative to bin/), and
    // where this build wrote it (tests and benchmarks run from other directories).
    std::vector<std::filesystem::path> tried;
    std::error_code ec;
    const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
    if (!ec) {
      tried.push_back(exe.parent_path() / PALPA_VDB_MODULE_NAME);
      tried.push_back(exe.parent_path() / PALPA_VDB_MODULE_INSTALL_REL / PALPA_VDB_MODULE_NAME);
    }
    tried.emplace_back(PALPA_VDB_MODULE_BUILD_PATH);
    std::string errors;
    for (const auto& path : tried) {
      if (!std::filesystem::exists(path, ec)) {
        errors += fmt::format("; {}: not found", path.string());
        continue;
      }
      void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
      if (handle == nullptr) {
        errors += fmt::format("; {}: {}", path.string(), dlerror());
        continue;
      }
      entry = reinterpret_cast<VolumeToMeshFn>(dlsym(handle, kVolumeToMeshSymbol));
      if (entry != nullptr) return;
      errors += fmt::format("; {}: no symbol {}", path.string(), kVolumeToMeshSymbol);
    }
    failure = fmt::format("cannot load the OpenVDB mesher {}{}", PALPA_VDB_MODULE_NAME, errors);
  });
  if (entry == nullptr) return std::unexpected(failure);
  entry(&field, &points, &triangles, &quads);
  return {};
}

}  // namespace internal

std::expected<TriangleMesh, Error> ExtractZeroSurface(const blob::FieldView& field) {
  const auto [lo, hi] = PhiRangeQ16(field);
  if (lo > 0 || hi <= 0)
    return std::unexpected(
        Error{fmt::format("no zero crossing: φ ranges over [{:.3f}, {:.3f}] voxels", lo / 65536.0, hi / 65536.0)});
  std::vector<Eigen::Vector3d> points;
  std::vector<std::array<int, 3>> triangles;
  std::vector<std::array<int, 4>> quads;
  if (auto done = internal::VolumeToMesh(field, points, triangles, quads); !done)
    return std::unexpected(Error{done.error()});
  // OpenVDB's grid and work space are freed by now, but as hundreds of thousands of small blocks
  // from TBB threads' arenas that glibc keeps: handed back, the peak RSS follows the output
  // (kitten, 1,200 cells: 880 -> see docs/tools.md).
  malloc_trim(0);

  TriangleMesh m;
  m.faces = std::move(triangles);
  m.faces.reserve(m.faces.size() + 2 * quads.size());
  for (const auto& q : quads) {
    auto at = [&](int a) -> const Eigen::Vector3d& {
      return points[static_cast<std::size_t>(q[static_cast<std::size_t>(a)])];
    };
    if ((at(0) - at(2)).squaredNorm() <= (at(1) - at(3)).squaredNorm()) {
      m.faces.push_back({q[0], q[1], q[2]});
      m.faces.push_back({q[0], q[2], q[3]});
    } else {
      m.faces.push_back({q[0], q[1], q[3]});
      m.faces.push_back({q[1], q[2], q[3]});
    }
  }
  quads = {};                      // memory follows the output (issue 21): no copy outlives its use
  m.vertices = std::move(points);  // index coordinates until the normals are done
  OrientOutward(m);                // OpenVDB's winding convention, made explicit: outward by enclosed volume

  // The normalised trilinear gradient; where it vanishes, the mean of the adjacent face normals.
  m.normals.resize(m.vertices.size());
  std::vector<std::size_t> flat;
  for (std::size_t v = 0; v < m.vertices.size(); ++v) {
    const Eigen::Vector3d g = TrilinearGradient(field, m.vertices[v]);
    const double len = g.norm();
    if (len > 1e-9) {
      m.normals[v] = g / len;
    } else {
      m.normals[v] = Eigen::Vector3d::Zero();
      flat.push_back(v);
    }
  }
  if (!flat.empty()) {
    std::vector<std::uint8_t> is_flat(m.vertices.size(), 0);
    for (const std::size_t v : flat) is_flat[v] = 1;
    for (std::size_t f = 0; f < m.faces.size(); ++f) {
      const Eigen::Vector3d n = FaceNormal(m, f);
      for (const int v : m.faces[f])
        if (is_flat[static_cast<std::size_t>(v)] != 0) m.normals[static_cast<std::size_t>(v)] += n;
    }
    for (const std::size_t v : flat) m.normals[v].normalize();
  }
  const Eigen::Vector3d origin(field.origin_m[0], field.origin_m[1], field.origin_m[2]);
  for (Eigen::Vector3d& x : m.vertices) x = origin + field.voxel_m * x;
  return m;
}

bool WritePly(const TriangleMesh& mesh, const std::function<bool(std::span<const std::byte>)>& sink) {
  const bool normals = mesh.normals.size() == mesh.vertices.size() && !mesh.normals.empty();
  std::string header = fmt::format(
      "ply\nformat binary_little_endian 1.0\ncomment palpa mesh: zero iso-surface, device-frame metres\n"
      "element vertex {}\nproperty float x\nproperty float y\nproperty float z\n",
      mesh.vertices.size());
  if (normals) header += "property float nx\nproperty float ny\nproperty float nz\n";
  header += fmt::format("element face {}\nproperty list uchar int vertex_indices\nend_header\n", mesh.faces.size());
  if (!sink(std::as_bytes(std::span(header)))) return false;
  constexpr std::size_t kChunk = 1 << 20;  // bytes handed to the sink at a time
  std::vector<std::byte> out;
  out.reserve(kChunk + 32);
  const auto flush = [&](bool force) {
    if (out.size() < kChunk && !force) return true;
    const bool ok = out.empty() || sink(out);
    out.clear();
    return ok;
  };
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
    std::array<float, 6> row{};
    for (int a = 0; a < 3; ++a) {
      row[static_cast<std::size_t>(a)] = static_cast<float>(mesh.vertices[v][a]);
      if (normals) row[static_cast<std::size_t>(a + 3)] = static_cast<float>(mesh.normals[v][a]);
    }
    Append(out, row.data(), (normals ? 6 : 3) * sizeof(float));  // little-endian host (palpa/fixed/q.h)
    if (!flush(false)) return false;
  }
  for (const auto& f : mesh.faces) {
    const std::uint8_t three = 3;
    Append(out, &three, 1);
    const std::array<std::int32_t, 3> idx{f[0], f[1], f[2]};
    Append(out, idx.data(), sizeof idx);
    if (!flush(false)) return false;
  }
  return flush(true);
}

std::vector<std::byte> ToPly(const TriangleMesh& mesh) {
  std::vector<std::byte> out;
  WritePly(mesh, [&](std::span<const std::byte> bytes) {
    out.insert(out.end(), bytes.begin(), bytes.end());
    return true;
  });
  return out;
}

std::string ToObj(const TriangleMesh& mesh) {
  const bool normals = mesh.normals.size() == mesh.vertices.size() && !mesh.normals.empty();
  std::string out = "# palpa mesh: zero iso-surface, device-frame metres\n";
  auto it = std::back_inserter(out);
  for (const auto& v : mesh.vertices) fmt::format_to(it, "v {:.9g} {:.9g} {:.9g}\n", v.x(), v.y(), v.z());
  if (normals)
    for (const auto& n : mesh.normals) fmt::format_to(it, "vn {:.6f} {:.6f} {:.6f}\n", n.x(), n.y(), n.z());
  for (const auto& f : mesh.faces) {
    if (normals)
      fmt::format_to(it, "f {0}//{0} {1}//{1} {2}//{2}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    else
      fmt::format_to(it, "f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
  }
  return out;
}

}  // namespace palpa::mesh
