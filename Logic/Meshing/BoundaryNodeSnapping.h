#pragma once
// Moves the nodes of a labelled tetrahedral mesh that lie on a tissue interface (or on the outer
// boundary) onto the label map's boundaries, so that the surfaces follow the tissues instead of
// the lattice's staircase, while every element keeps a bounded quality.
//
// The interface between two tissues A and B is where their indicator functions (0/1 per voxel,
// interpolated trilinearly) are equal: on the voxel faces between them, so that the volumes match
// the voxels'; "outside" (every label not meshed, and beyond the image) counts as a tissue. Each
// interface node looks along its incident mesh edges (both ways, up to 3/4 of their length, and only
// towards the tetrahedra of the region it is not in, so a thin structure is never crossed) for the
// nearest crossing of an interface between two of its incident regions, then moves there in a few
// Gauss-Seidel passes
// in node order; a move is accepted only if every incident tetrahedron keeps a positive volume and
// dihedral angles within [minimumDihedralDegrees, 180 - minimumDihedralDegrees], else its step is
// halved. Deterministic: fixed order, no randomness.
#include "ImageTypes.h"

#include <array>
#include <cstddef>
#include <vector>

namespace brainshift {

struct TetrahedralMeshArrays {
  std::vector<std::array<double, 3>> points;            ///< LPS mm
  std::vector<std::array<long long, 4>> tetrahedra;     ///< positive orientation
  std::vector<int> labels;                              ///< one per tetrahedron
};

struct SnappingParameters {
  double minimumDihedralDegrees = 12.0;
  int passes = 4;
  int halvings = 5;
  double searchFraction = 0.75; ///< of each incident edge's length (0.5 leaves more staircase, 1 costs volume)
};

struct SnappingSummary {
  std::size_t interfaceNodes = 0, nodesOnInterface = 0, nodesPartlyMoved = 0, nodesWithoutCrossing = 0;
};

SnappingSummary snapInterfaceNodes(TetrahedralMeshArrays& mesh, const LabelImage& image, const std::vector<int>& tissues,
                                   const SnappingParameters& parameters = {});

} // namespace brainshift
