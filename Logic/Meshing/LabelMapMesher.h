#pragma once
// A conforming tetrahedral mesh of several tissues of a label map at once (Warfield et al. built
// theirs in the spirit of marching tetrahedra): a Kuhn lattice of cubes, each cut into six
// tetrahedra that share faces with their neighbours by construction, each tetrahedron taking the
// tissue at its centroid. Graded: the cubes have the target edge length near every tissue
// interface, the brain's outer surface and a region of interest, and grow (up to 2^levels times)
// with the distance from them, refined by conforming bisection (GradedKuhnLattice.h): no
// hanging nodes; the tissues share their faces.
// The nodes on a tissue interface or the outer boundary are then moved onto the label map's
// boundaries (BoundaryNodeSnapping.h), each move guarded so that no dihedral angle leaves
// [12, 168] degrees and no element inverts: the surfaces follow the tissues, not a staircase, and
// each tissue's volume is within 3 % of its voxels' at 1.5-2 mm on 1 mm voxels. Boundary surfaces
// (per tissue, or of several together) are extracted as outward triangles with the mesh node each
// point is.
//
// The CGAL Mesh_3 backend (CgalLabelMapMesher.h) gives the same output: LPS mm, cell array Label,
// only the chosen tissues, positive tetrahedra.
// The CGAL backend meshes at a uniform size (grading is the lattice's).
#include "BrainShiftErrors.h"
#include "ImageTypes.h"

#include <vtkPolyData.h>
#include <vtkSmartPointer.h>
#include <vtkUnstructuredGrid.h>

#include <array>
#include <map>
#include <optional>
#include <set>
#include <vector>

namespace brainshift {

/// Lattice: the Kuhn lattice with snapped boundary nodes (fast, structured). Cgal: CGAL Mesh_3's
/// Delaunay refinement of the labelled image (needs a build with CGAL).
enum class MeshingBackend { Lattice, Cgal };

struct MeshingParameters {
  MeshingBackend backend = MeshingBackend::Lattice;
  double resolutionMm = 3.0;          ///< edge length of the lattice's cubes (CGAL: facet and cell size)
  std::vector<int> labels{2, 3, 4};   ///< the tissues meshed
  bool snapToBoundaries = true;       ///< move interface nodes onto the label boundaries
  double minimumDihedralDegrees = 12; ///< no snapping move takes an element's dihedral angle below this
  /// Graded resolution (lattice): away from the features (tissue interfaces, the outer surface,
  /// the region of interest) the cube edge may grow by this many mm per mm of distance; 0 keeps
  /// the lattice uniform. The coarsest cubes are 2^coarseningLevels times resolutionMm.
  double gradingRate = 0.0;
  int coarseningLevels = 2;
  struct Sphere {
    std::array<double, 3> centerLps{};
    double radiusMm = 0;
  };
  std::optional<Sphere> regionOfInterest; ///< meshed at resolutionMm throughout
  CancelFlag cancel = nullptr;            ///< polled between the phases: CancelledError when set
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

struct Configuration;
/// The mesh stage's parameters from the one configuration (resolution, tissues, backend, grading,
/// region of interest): what the command line and the Meshing panel start from.
MeshingParameters meshingParametersFrom(const Configuration& configuration);

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
