// Reading oriented point sets (points + outward unit normals), the input of paper §3.
#pragma once

#include <expected>
#include <filesystem>
#include <vector>

#include <Eigen/Core>

#include "palpa/field/error.h"

namespace palpa::field {

// Oriented points in model units. positions[i] and normals[i] belong together; normals are outward
// and unit length. Both vectors always have the same size.
struct PointSet {
  std::vector<Eigen::Vector3d> positions;
  std::vector<Eigen::Vector3d> normals;
};

// Reads an ASCII .xyz or .pwn file (extension case-insensitive): one point per line as six
// whitespace-separated numbers `x y z nx ny nz`. `#` starts a comment; blank lines and trailing
// whitespace are allowed. Normals are normalised to unit length.
//
// Errors (message starts with the file name, plus ":LINE" for a line error):
//   unknown extension; missing or unreadable file; a line without exactly six numbers
//   ("data/x.xyz:17: expected 6 numbers, found 5"); a token that is not a number; non-finite
//   position; zero-length or non-finite normal; fewer than 4 points.
std::expected<PointSet, Error> ReadPoints(const std::filesystem::path& path);

}  // namespace palpa::field
