// Internal: the PLY reader behind ReadPoints (palpa/field/point_io.h).
#pragma once

#include <expected>
#include <optional>
#include <string>
#include <string_view>

#include <Eigen/Core>

#include "palpa/field/error.h"
#include "palpa/field/point_io.h"

namespace palpa::field::detail {

/// Validates one oriented point and appends it (normal normalised), or says what is wrong with it.
using AddPoint = std::optional<std::string> (*)(PointSet& points, const Eigen::Vector3d& position,
                                                const Eigen::Vector3d& normal);

/// Parses the PLY file `name` whose bytes are `text`; see ReadPoints for the contract.
std::expected<PointSet, Error> ReadPly(const std::string& name, std::string_view text, const AddPoint& add);

}  // namespace palpa::field::detail
