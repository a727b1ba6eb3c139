// The only translation unit that includes CGAL (slow to compile): keep it small.
#include <CGAL/AABB_face_graph_triangle_primitive.h>
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Side_of_triangle_mesh.h>
#include <CGAL/Surface_mesh.h>

#include <array>
#include <cmath>
#include <vector>

#include "palpa/mesh/mesh_distance.h"

namespace palpa::mesh {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Surface = CGAL::Surface_mesh<Point>;
using Primitive = CGAL::AABB_face_graph_triangle_primitive<Surface>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, Primitive>>;
using SideOf = CGAL::Side_of_triangle_mesh<Surface, Kernel, CGAL::Default, Tree>;

Point ToPoint(const Eigen::Vector3d& p) { return {p.x(), p.y(), p.z()}; }

}  // namespace

struct ExactMeshDistance::Impl {
  Surface surface;
  Tree tree;
  std::unique_ptr<SideOf> side;  // closed meshes only
};

ExactMeshDistance::ExactMeshDistance(const TriangleMesh& mesh, bool closed) : impl_(std::make_unique<Impl>()) {
  Surface& s = impl_->surface;
  std::vector<Surface::Vertex_index> v;
  v.reserve(mesh.vertices.size());
  for (const auto& p : mesh.vertices) v.push_back(s.add_vertex(ToPoint(p)));
  for (const auto& f : mesh.faces)
    s.add_face(v[static_cast<std::size_t>(f[0])], v[static_cast<std::size_t>(f[1])], v[static_cast<std::size_t>(f[2])]);
  impl_->tree.insert(faces(s).first, faces(s).second, s);
  impl_->tree.build();
  impl_->tree.accelerate_distance_queries();
  if (closed) impl_->side = std::make_unique<SideOf>(impl_->tree);
  // Any lazily built search structure is built now, on one thread, before concurrent queries.
  if (!mesh.vertices.empty()) (void)impl_->tree.closest_point(ToPoint(mesh.vertices[0]));
}

ExactMeshDistance::~ExactMeshDistance() = default;

double ExactMeshDistance::UnsignedDistance(const Eigen::Vector3d& p) const {
  return std::sqrt(CGAL::to_double(impl_->tree.squared_distance(ToPoint(p))));
}

double ExactMeshDistance::UnsignedDistance(const Eigen::Vector3d& p, Eigen::Vector3d& hint) const {
  const Point q = ToPoint(p);
  const Point c = impl_->tree.closest_point(q, ToPoint(hint));
  hint = Eigen::Vector3d(c.x(), c.y(), c.z());
  return std::sqrt(CGAL::to_double(CGAL::squared_distance(q, c)));
}

std::optional<ExactMeshDistance::RayHit> ExactMeshDistance::FirstHit(const Eigen::Vector3d& origin,
                                                                     const Eigen::Vector3d& dir) const {
  const Kernel::Ray_3 ray(ToPoint(origin), Kernel::Vector_3(dir.x(), dir.y(), dir.z()));
  const auto hit = impl_->tree.first_intersection(ray);
  if (!hit) return std::nullopt;
  const Point* p = boost::get<Point>(&hit->first);
  if (p == nullptr) return std::nullopt;  // a segment: the ray runs along a face (grazing)
  return RayHit{Eigen::Vector3d(p->x(), p->y(), p->z()), static_cast<std::size_t>(hit->second.idx())};
}

int ExactMeshDistance::NearSide(const Eigen::Vector3d& p) const {
  const Point q = ToPoint(p);
  const auto [c, face] = impl_->tree.closest_point_and_primitive(q);
  const Surface& s = impl_->surface;
  std::array<Point, 3> t;
  std::size_t k = 0;
  for (const auto vertex : vertices_around_face(s.halfedge(face), s)) t[k++] = s.point(vertex);
  const Kernel::Vector_3 normal = CGAL::cross_product(t[1] - t[0], t[2] - t[0]);
  const double d = CGAL::to_double((q - c) * normal);
  return d < 0 ? -1 : d > 0 ? 1 : 0;
}

Eigen::Vector3d ExactMeshDistance::AnySurfacePoint() const {
  const Point& v = impl_->surface.point(*impl_->surface.vertices().begin());
  return {v.x(), v.y(), v.z()};
}

int ExactMeshDistance::Side(const Eigen::Vector3d& p) const {
  if (!impl_->side) return NearSide(p);  // open: no inside to decide; eval signs far nodes by w
  switch ((*impl_->side)(ToPoint(p))) {
    case CGAL::ON_BOUNDED_SIDE:
      return -1;
    case CGAL::ON_BOUNDARY:
      return 0;
    case CGAL::ON_UNBOUNDED_SIDE:
      return 1;
  }
  return 1;
}

double ExactMeshDistance::SignedDistance(const Eigen::Vector3d& p) const {
  const int side = Side(p);
  return side == 0 ? 0.0 : side * UnsignedDistance(p);
}

}  // namespace palpa::mesh
