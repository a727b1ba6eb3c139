// Enclosed outside pockets and floating inside islands that no sample bounds (issue 20): hollows
// and specks that a field's side rules leave in a closure or the air, far from every sample.
// Host only.
#pragma once

#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "palpa/field/sparse_field.h"

namespace palpa::field {

// The default reaches of both passes below: a sample bounds a component within this many voxels,
// or within this many of its own spacings on the component's side.
inline constexpr double kPocketReachVoxels = 3.0;
inline constexpr double kPocketReachSpacings = 1.0;

struct PocketFill {
  std::size_t components = 0;  // pockets filled, or islands cut
  std::size_t nodes = 0;       // their nodes, set to the other side
};

// Fills every outside pocket of `field` that no sample bounds, and returns what it filled.
// A pocket is a 6-connected set of outside nodes (phi > 0) that no path of outside nodes joins to
// a grid face node. A sample bounds it at a node of the pocket with an inside axis neighbour (its
// zero surface passes within a voxel) when the sample lies within reach_voxels voxels of that
// node, or within reach_spacings x its own spacing with the node in front of it ((node - sample)
// . normal > 0): a cavity's wall is sampled, and its samples face into it. A pocket that every
// sample near its surface has behind it is a hollow that the side rules left inside a closure,
// which nothing scanned shows; one beside a surface (within reach_voxels) stays whatever the
// normals say, as a small bubble the samples leave unsettled.
// A filled node takes minus its distance to the nearest sample (voxels, at least 1e-6, clamped to
// the band), as HermiteField's far pass gives a node far from the surface; so does an inside node
// (above -band) within a band's steps of a filled pocket farther than reach_voxels from every
// sample, where that is deeper: the pocket's surface had held it near 0. Call before
// ProjectLipschitz, which then bounds every value by its neighbours'.
// `positions`, `normals` (unit, outward): the samples, metres in the grid's frame; `spacing`: each
// one's distance to its 8th nearest (metres; HermiteField's SampleSpacing); the same sizes. A
// face node at or below 0 is no seed: the caller (HermiteField) has set every face node outside.
// Cost: a flood fill from the faces over 8-node rows of each allocated brick (a uniform outside
// brick is one unit), O(allocated bricks) and no sample search when nothing is enclosed; each
// enclosed node is visited once, the samples' k-d tree built only then. Deterministic.
// docs/field-methods.md § Enclosed pockets and floating islands that no sample bounds.
PocketFill FillSamplelessPockets(SparseField& field, const std::vector<Eigen::Vector3d>& positions,
                                 const std::vector<Eigen::Vector3d>& normals, const std::vector<double>& spacing,
                                 double reach_voxels = kPocketReachVoxels,
                                 double reach_spacings = kPocketReachSpacings);

// The same for the inside: cuts every island of `field` that no sample bounds, and returns what it
// cut. An island is a 6-connected set of inside nodes (phi <= 0) none of which lies within
// reach_voxels voxels of a sample (the inside is flooded from its nodes that do). A sample bounds
// it at a node with an outside axis neighbour when it lies within reach_spacings x its own spacing
// with the node behind it ((node - sample) . normal < 0). An island that no sample bounds is
// solid floating where nothing was scanned (a speck the side rules left in the air, a piece of a
// closure cut off); its nodes take their distance to the nearest sample (voxels, at least 1e-6,
// clamped to the band), and so does an outside node (below +band) within a band's steps of it
// farther than reach_voxels from every sample, where that is larger. Same arguments, units and
// cost as FillSamplelessPockets, plus a sphere of nodes about each sample for the flood's seeds.
PocketFill CutSamplelessIslands(SparseField& field, const std::vector<Eigen::Vector3d>& positions,
                                const std::vector<Eigen::Vector3d>& normals, const std::vector<double>& spacing,
                                double reach_voxels = kPocketReachVoxels, double reach_spacings = kPocketReachSpacings);

}  // namespace palpa::field
