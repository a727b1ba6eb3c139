// Degenerate samples of a real point set (issue 20): a zero-length or non-finite normal (read with
// ReadOptions::keep_bad_normals, which stores it as (0, 0, 0)) and exact duplicates carry no
// orientation or no new information, and a duplicate gives the neighbour searches a zero spacing.
// They are dropped before the build, counted, and the first of each kind is named.
#pragma once

#include <cstddef>
#include <expected>
#include <optional>
#include <string>

#include "palpa/field/error.h"
#include "palpa/field/point_io.h"

namespace palpa::field {

struct DroppedSamples {
  std::size_t bad_normals = 0;                  ///< normal (0, 0, 0): zero-length or non-finite in the file
  std::size_t duplicates = 0;                   ///< same position as an earlier point (bit for bit)
  std::optional<std::size_t> first_bad_normal;  ///< index in the points as read
  std::optional<std::size_t> first_duplicate;   ///< index in the points as read
  std::optional<std::size_t> duplicate_of;      ///< the earlier point first_duplicate repeats
  std::string first_bad_normal_place;           ///< PointPlace of first_bad_normal ("" if none)
  std::string first_duplicate_place;            ///< PointPlace of first_duplicate ("" if none)
  std::string duplicate_of_place;               ///< PointPlace of duplicate_of ("" if none)
  std::size_t kept = 0;                         ///< points left

  std::size_t Total() const { return bad_normals + duplicates; }
  /// "2 samples with a zero-length or non-finite normal (first: scan.xyz:17) and 1 exact duplicate
  /// (first: scan.xyz:40, the position of scan.xyz:12)"; empty when nothing was dropped.
  std::string Describe() const;
};

/// Removes from `points` every point whose normal is (0, 0, 0) and every point whose position
/// equals an earlier point's exactly (its normal is dropped with it), keeping the order of the
/// rest; `points.lines` follows. `file` names the points' file in the places (PointPlace).
/// O(n log n). Positions must be finite (ReadPoints ensures it).
DroppedSamples DropDegenerateSamples(PointSet& points, const std::string& file);

}  // namespace palpa::field
