// Area-uniform oriented points on a closed triangle mesh: turns any closed mesh into a point set
// whose true surface is known, for `palpa sample` and for accuracy tests of field methods. Non-RT.
#pragma once

#include <cstdint>
#include <string>

#include "palpa/field/point_io.h"
#include "palpa/mesh/triangle_mesh.h"

namespace palpa::mesh {

/// `count` points drawn uniformly by area from the faces of `mesh` (each face chosen with
/// probability area/total, then a uniform point inside it by the square-root barycentric map,
/// Osada et al. 2002 eq. 1), each with its face's unit normal. Units are the mesh's.
///
/// The mesh must be closed and consistently oriented (CheckClosedOriented); the normals are made
/// outward whatever the file's winding (the sign of SignedVolume decides, as in OrientOutward).
/// Deterministic: the same mesh, count and seed give bit-identical points on every platform
/// (std::mt19937_64, whose output sequence the C++ standard fixes, and no library distributions).
/// Errors: count 0; the CheckClosedOriented errors; zero surface area.
std::expected<field::PointSet, Error> SampleSurface(const TriangleMesh& mesh, std::size_t count, std::uint64_t seed,
                                                    const std::string& name = "mesh");

/// The points as ASCII `x y z nx ny nz` lines (9 significant digits), the .xyz format that
/// field::ReadPoints reads.
std::string ToXyzText(const field::PointSet& points);

}  // namespace palpa::mesh
