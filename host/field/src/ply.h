// Internal: the PLY reader behind ReadPoints (palpa/field/point_io.h).
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>

#include <Eigen/Core>

#include "palpa/field/point_io.h"

namespace palpa::field::detail {

/// The PLY header must end ("end_header") within this many bytes: a file without one is refused
/// after reading only this much.
inline constexpr std::size_t kMaxPlyHeaderBytes = 64 * 1024;

/// Validates one oriented point and appends it (normal normalised), or says what is wrong with it.
using AddPoint = std::optional<std::string> (*)(PointSet& points, const Eigen::Vector3d& position,
                                                const Eigen::Vector3d& normal);

/// ReadPoints' rules for one point: a finite position, a finite non-zero normal, which is
/// normalised. Appends it, or says what is wrong. (ply.cc)
std::optional<std::string> AddOrientedPoint(PointSet& points, const Eigen::Vector3d& position,
                                            const Eigen::Vector3d& normal);

/// Parses the PLY file `name` whose bytes are `text` into `points` (appended); see ReadPoints for
/// the contract. With `allow_missing_normals`, a vertex element without nx ny nz is read as bare
/// positions (normals (0, 0, 0), points.has_normals = false; ReadOptions::allow_missing_normals). Returns the error, or
/// nothing. (Not std::expected<PointSet>: the fuzzer's clang 14 cannot destroy libstdc++ 12's expected of a non-trivial
/// type.)
std::optional<std::string> ReadPly(const std::string& name, std::string_view text, const AddPoint& add,
                                   PointSet& points, bool allow_missing_normals = false);

}  // namespace palpa::field::detail
