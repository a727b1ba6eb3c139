// Sphere packing of oriented points, paper §3.1 eq. 2-3.
//
// For point i the packed ball is tangent to the surface at P_i with inward normal -n_i. Point j
// constrains it when -n_i . a_ij > 0 (a_ij = P_j - P_i): the ball through P_j has radius
// r_ij = |a_ij|^2 / (2 (-n_i . a_ij))  (eq. 2, = |a_ij| sec(theta_ij) / 2).
// The packing radius is r_i = min_j r_ij (eq. 3), capped at r_max; the centre c_i = P_i - r_i n_i.
// Points closer to P_i than 1e-12 x (longest bounding-box side) count as P_i itself and are
// skipped (duplicates would give r = 0).
//
// Callers pass r_max = the longest bounding-box side of the points (BuildErosionField does):
// a ball that no other point limits is then still finite and no bigger than the object.
// Preconditions: positions.size() == normals.size() (else the result is empty); normals unit
// length; r_max > 0 (may be +infinity). Units: those of `positions`.
#pragma once

#include <vector>

#include <Eigen/Core>

namespace palpa::field {

struct Packing {
  std::vector<Eigen::Vector3d> centres;  // c_i = P_i - r_i n_i
  std::vector<double> radii;             // r_i
};

// Reference O(N^2) evaluation of eq. 3; single-threaded.
std::vector<double> PackingRadiiBruteForce(const std::vector<Eigen::Vector3d>& positions,
                                           const std::vector<Eigen::Vector3d>& normals, double r_max);

// Same result as PackingRadiiBruteForce (bit for bit), via a k-d tree and TBB threads.
// Balls tangent at P_i with the same inward normal are nested, and P_j is strictly inside the
// ball of radius r iff r_ij < r; so an upper bound r0 (from the 16 nearest neighbours and a few
// probes of the nearest neighbours of the ball centre P_i - r0 n_i, or r_max)
// and one radius search of the ball (P_i - r0 n_i, r0) find every point that can lower it.
// Deterministic for any thread count.
std::vector<double> PackingRadii(const std::vector<Eigen::Vector3d>& positions,
                                 const std::vector<Eigen::Vector3d>& normals, double r_max);

// PackingRadii plus the centres.
Packing PackSpheres(const std::vector<Eigen::Vector3d>& positions, const std::vector<Eigen::Vector3d>& normals,
                    double r_max);

}  // namespace palpa::field
