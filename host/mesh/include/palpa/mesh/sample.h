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

/// A virtual range scan of `mesh` (issue 20's robustness benchmark: a real scan's open sides,
/// occlusions and range noise): `views` pinhole cameras on the upper hemisphere (+z up, as a
/// tabletop scanner that never sees the underside), at elevations spread evenly between 10 and
/// 80 degrees (in sine) and azimuths by the golden angle, 2.5 bounding radii from the bounding
/// box's centre, each looking at it with a field of view just holding the bounding sphere. Each
/// camera casts a jittered square grid of rays; the first hit of each ray (ExactMeshDistance::
/// FirstHit) is kept with its face's outward normal unless the ray grazes the face (more than 80
/// degrees from its normal, which a real scanner does not return). `range_noise` (model units)
/// moves each point along its ray by Gaussian noise (Box-Muller on std::mt19937_64: the same
/// output on every platform); normals are the faces'. Twice `count` rays are cast over all views;
/// when more than `count` rays hit, `count` of the hits are kept, chosen by the seed. So the
/// result has at most `count` points, fewer when the mesh fills little of the views.
/// Errors: count or views 0; the CheckClosedOriented errors.
std::expected<field::PointSet, Error> RangeScan(const TriangleMesh& mesh, std::size_t count, int views,
                                                double range_noise, std::uint64_t seed,
                                                const std::string& name = "mesh");

/// The points as ASCII `x y z nx ny nz` lines (9 significant digits), the .xyz format that
/// field::ReadPoints reads.
std::string ToXyzText(const field::PointSet& points);

}  // namespace palpa::mesh
