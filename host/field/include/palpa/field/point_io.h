// Reading oriented point sets (points + outward unit normals), the input of paper §3.
#pragma once

#include <expected>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "palpa/field/error.h"

namespace palpa::field {

// Oriented points in model units. positions[i] and normals[i] belong together; normals are outward
// and unit length. Both vectors always have the same size.
struct PointSet {
  std::vector<Eigen::Vector3d> positions;
  std::vector<Eigen::Vector3d> normals;
  /// With ReadOptions::keep_bad_normals only: the file line of each point (.xyz, .pwn; empty for
  /// PLY, whose points are named by vertex number), for messages about single points (PointPlace).
  std::vector<std::size_t> lines;
  /// False when the file gave positions only (ReadOptions::allow_missing_normals: `.xyz` lines
  /// of three numbers, a PLY vertex without nx ny nz); normals are then all (0, 0, 0) until
  /// EstimateNormals (normals.h) fills them.
  bool has_normals = true;
};

struct ReadOptions {
  /// Keep a point whose normal is zero-length or not finite, with the normal (0, 0, 0), instead
  /// of refusing the file: the caller drops it and says so (palpa build, issue 20: a real scan
  /// with 2 such normals of 4,387 must not be refused whole). Non-finite positions stay errors.
  bool keep_bad_normals = false;
  /// Accept points without normals (issue 20: a scanner's bare positions), for a caller that
  /// estimates them: `.xyz`/`.pwn` whose every line has three numbers `x y z`, and PLY whose
  /// vertex has no nx ny nz. The normals are (0, 0, 0) and PointSet::has_normals is false. A file
  /// that mixes three- and six-number lines is refused at the first line that differs. Implies
  /// keep_bad_normals' `lines` bookkeeping for .xyz/.pwn.
  bool allow_missing_normals = false;
};

// Reads oriented points, by extension (case-insensitive):
//   .xyz, .pwn  ASCII, one point per line as six whitespace-separated numbers `x y z nx ny nz`.
//               `#` starts a comment; blank lines and trailing whitespace are allowed.
//   .ply        PLY 1.0 (ascii, binary_little_endian or binary_big_endian; docs/input-formats.md):
//               the `vertex` element's scalar properties x y z nx ny nz, of any PLY number type;
//               other properties and elements (colours, faces, lists) are skipped.
// Normals are normalised to unit length. Nothing is returned unless the whole file is good.
//
// Errors (message starts with the file name, plus ":LINE" for a line error, or ": byte N" in a
// binary PLY body):
//   unknown extension; missing or unreadable file; a line without exactly six numbers
//   ("data/x.xyz:17: expected 6 numbers, found 5"); a token that is not a number; non-finite
//   position; zero-length or non-finite normal; fewer than 4 points. PLY also: a bad or
//   unterminated header (its line), no vertex element or a missing x … nz property, a body that
//   ends early ("scan.ply: byte 1234: the file ends inside vertex 77 of 100 'nz' (2 of 4 bytes
//   there)"), and a bad point, named by its vertex number.
// With options.keep_bad_normals, a zero or non-finite normal is kept as (0, 0, 0) (see ReadOptions);
// with options.allow_missing_normals, a file of bare positions is read (PointSet::has_normals).
std::expected<PointSet, Error> ReadPoints(const std::filesystem::path& path, const ReadOptions& options = {});

// Where point `index` of `points` (read from `file`) is, for messages: "scan.xyz:17" (its line,
// when points.lines has it) or "scan.ply: vertex 16" (0-based, as the PLY reader's errors).
std::string PointPlace(const std::string& file, const PointSet& points, std::size_t index);

}  // namespace palpa::field
