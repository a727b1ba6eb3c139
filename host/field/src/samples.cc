#include "palpa/field/samples.h"

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <vector>

#include <fmt/format.h>

namespace palpa::field {

std::string DroppedSamples::Describe() const {
  std::string out;
  if (bad_normals > 0) {
    out = fmt::format("{} sample{} with a zero-length or non-finite normal (first: {})", bad_normals,
                      bad_normals == 1 ? "" : "s", first_bad_normal_place);
  }
  if (duplicates > 0) {
    if (!out.empty()) out += " and ";
    out += fmt::format("{} exact duplicate{} (first: {}, the position of {})", duplicates, duplicates == 1 ? "" : "s",
                       first_duplicate_place, duplicate_of_place);
  }
  return out;
}

DroppedSamples DropDegenerateSamples(PointSet& points, const std::string& file) {
  const std::size_t n = points.positions.size();
  DroppedSamples d;
  std::vector<std::uint8_t> drop(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    if (points.normals[i] == Eigen::Vector3d::Zero()) {
      drop[i] = 1;
      ++d.bad_normals;
      if (!d.first_bad_normal) d.first_bad_normal = i;
    }
  }
  // Exact duplicates: sort indices by position (ties by index), so each run of equal positions
  // starts with its earliest point; every later one in the run is dropped.
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t{0});
  const auto& p = points.positions;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    for (Eigen::Index ax = 0; ax < 3; ++ax)
      if (p[a][ax] != p[b][ax]) return p[a][ax] < p[b][ax];
    return a < b;
  });
  std::size_t run_first = n;  // first point of the current run with a usable normal
  for (std::size_t r = 0; r < n; ++r) {
    const std::size_t i = order[r];
    if (r == 0 || p[i] != p[order[r - 1]]) run_first = n;
    if (drop[i]) continue;  // already dropped for its normal
    if (run_first == n) {
      run_first = i;
      continue;
    }
    drop[i] = 1;
    ++d.duplicates;
    if (!d.first_duplicate || i < *d.first_duplicate) {
      d.first_duplicate = i;
      d.duplicate_of = run_first;
    }
  }
  if (d.first_bad_normal) d.first_bad_normal_place = PointPlace(file, points, *d.first_bad_normal);
  if (d.first_duplicate) {
    d.first_duplicate_place = PointPlace(file, points, *d.first_duplicate);
    d.duplicate_of_place = PointPlace(file, points, *d.duplicate_of);
  }
  std::size_t w = 0;
  const bool lines = points.lines.size() == n;
  for (std::size_t i = 0; i < n; ++i) {
    if (drop[i]) continue;
    points.positions[w] = points.positions[i];
    points.normals[w] = points.normals[i];
    if (lines) points.lines[w] = points.lines[i];
    ++w;
  }
  points.positions.resize(w);
  points.normals.resize(w);
  if (lines) points.lines.resize(w);
  d.kept = w;
  return d;
}

}  // namespace palpa::field
