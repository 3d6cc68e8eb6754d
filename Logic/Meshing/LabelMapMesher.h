#pragma once
// A conforming tetrahedral mesh of several tissues of a label map at once (Warfield et al. built
// theirs in the spirit of marching tetrahedra): a Kuhn lattice of cubes of the target edge length,
// each cut into six tetrahedra that share faces with their neighbours by construction, each
// tetrahedron taking the tissue at its centroid. No hanging nodes; the tissues share their faces.
// Boundary surfaces (per tissue, or of several together) are extracted as outward triangles with
// the mesh node each point is.
//
// Not yet (issue 5): boundary nodes moved onto the label boundaries with quality protected (the
// surfaces are staircased at the lattice's resolution), graded resolution, the CGAL backend.
#include "BrainShiftErrors.h"
#include "ImageTypes.h"

#include <vtkPolyData.h>
#include <vtkSmartPointer.h>
#include <vtkUnstructuredGrid.h>

#include <map>
#include <set>
#include <vector>

namespace brainshift {

struct MeshingParameters {
  double resolutionMm = 3.0;          ///< edge length of the lattice's cubes
  std::vector<int> labels{2, 3, 4};   ///< the tissues meshed
  void validate(const LabelImage& labels) const;
};

struct MeshQuality {
  std::size_t nodes = 0, tetrahedra = 0;
  double minimumDihedralDegrees = 0, maximumDihedralDegrees = 0;
  std::size_t invertedOrFlat = 0;
  /// Radius ratio (3 r_in / r_circ, 1 for the regular tetrahedron) in 10 bins over [0, 1].
  std::vector<std::size_t> radiusRatioHistogram;
  std::map<int, double> meshVolumeMl, voxelVolumeMl;
};

struct LabelMapMesh {
  vtkSmartPointer<vtkUnstructuredGrid> mesh; ///< LPS mm, cell array "Label"
  MeshQuality quality;
  Warnings warnings;
};

/// Meshes the chosen tissues. InputError for an empty label map, tissues absent from it, a
/// resolution finer than the voxels or coarser than the tissues; a tissue that vanishes at the
/// chosen resolution is an error naming it.
LabelMapMesh meshLabelMap(const LabelImage& labels, const MeshingParameters& parameters);

/// The quality figures of a tetrahedral mesh (and the voxel volume of each tissue of `labels`).
MeshQuality measureMeshQuality(vtkUnstructuredGrid* mesh, const LabelImage* labels);

/// The boundary of the union of the tetrahedra whose label is in `tissues`: triangles oriented
/// outward, with the point array "MeshNodeId" (the mesh node each surface point is).
vtkSmartPointer<vtkPolyData> boundarySurface(vtkUnstructuredGrid* mesh, const std::set<int>& tissues);

} // namespace brainshift
