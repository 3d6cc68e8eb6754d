#pragma once
// The resampling transform of the intraoperative update on the intraoperative grid: for each
// intraoperative voxel y, the preoperative point x = y + d(y) it shows (../shared/CONTRACT.md).
//
// y is first brought into the model frame by the rigid transform, p = R(y). The finite element
// solution maps each preoperative point X of the mesh to its deformed place X + u(X), piecewise
// linearly over the tetrahedra; its inverse is exact: p is located in the deformed tetrahedron that
// holds it, and its barycentric coordinates there give X = sum lambda_k X_k. Outside the deformed
// mesh the non-rigid correction X - p fades smoothly to zero (a normalised Gaussian extension of the
// correction from the mesh, about `fallbackSigmaMm` wide), so far from the brain the mapping is the
// rigid one. Next to the mesh the correction first continues across the brain's boundary (in
// order of distance from the mesh, each voxel takes its nearer neighbours') and blends into the
// fade over a band: the boundary the update shows is the deformed mesh's, not pulled back towards
// the preoperative one by the fade's average of the corrections deeper inside (where the brain sank
// under a craniotomy, the gap above it shows the preoperative space above the brain, not brain).
// The Jacobian determinant of y -> x flags folding (<= 0).
#include "BrainShiftErrors.h"
#include "ImageTypes.h"
#include "TransformIO.h"

#include <vtkUnstructuredGrid.h>

#include <string>

namespace brainshift {

struct DeformationFieldParameters {
  /// The fade's width; it grows with the largest correction on the mesh's boundary (at least
  /// 1.2 times it), so that the fade does not fold the space between the brain and the skull.
  double fallbackSigmaMm = 4.0;
  /// The band outside the mesh over which the continued correction blends into the fade, beyond the
  /// first layer of voxels (within the grid's largest spacing), which keeps it whole: at least
  /// `continuationMinimumMm`, and wide enough that the blend compresses the space along it by at
  /// most `continuationMaximumCompression` (the band's width is the largest difference between
  /// the continued correction and the fade within continuationMaximumMm, divided by it), up to
  /// `continuationMaximumMm`. 0 for continuationMaximumMm: the fade alone. 30 mm takes a 20 mm sink
  /// at 2/3 (15 mm folded the gap above the 20 mm scenarios' sunken brain and showed preoperative
  /// brain in it, up to 16 mm above the true boundary).
  double continuationMinimumMm = 3.0, continuationMaximumMm = 30.0, continuationMaximumCompression = 2.0 / 3.0;
};

struct DeformationField {
  DisplacementFieldImage::Pointer field; ///< x = y + d(y), LPS mm, rigid part included
  ScalarImage::Pointer jacobianDeterminant;
  std::size_t voxels = 0, meshVoxels = 0, foldedVoxels = 0;
  /// Folded voxels inside the deformed mesh (the brain); the rest fold in the continuation outside
  /// it, where a sink deeper than the band can take (about 2/3 of continuationMaximumMm) compresses
  /// the gap and air above the brain past zero.
  std::size_t foldedVoxelsInMesh = 0;
  std::size_t invertedDeformedTetrahedra = 0; ///< tetrahedra the displacement turned inside out
  double minimumJacobian = 0, maximumNonRigidMm = 0;
  double fallbackSigmaMm = 0; ///< the fade's width used
  double continuationBandMm = 0; ///< the band's width used (0: none)
  std::size_t continuedVoxels = 0; ///< voxels outside the mesh given a continued correction
  double locateSeconds = 0, fallbackSeconds = 0, jacobianSeconds = 0;
};

/// `mesh`: mesh.vtu after the solve (point array "Displacement", preoperative frame). InputError
/// naming `meshName` when the mesh has no displacement or non-tetrahedral cells.
DeformationField intraopToPreopField(vtkUnstructuredGrid* mesh, const SpatialTransform& rigidIntraopToPreop,
                                     const ImageGeometry& intraopGrid, const DeformationFieldParameters& parameters,
                                     const std::string& meshName = "the mesh");

/// The voxels of `grid` where the solve put the tissue `label` of the mesh (cell array "Label"):
/// those whose point R(y) lies in one of its deformed tetrahedra (1; else 0). Rasterised
/// tetrahedron by tetrahedron: its cost follows the tissue, not the grid. InputError naming
/// `meshName` when the mesh has no displacement or labels.
MaskImage::Pointer voxelsOfDeformedTissue(vtkUnstructuredGrid* mesh, LabelPixel label, const SpatialTransform& rigidIntraopToPreop,
                                          const ImageGeometry& grid, const std::string& meshName = "the mesh");

/// A linear transform alone as a field on `grid`: x = T(y) = y + d(y) (the rigid result in the
/// form of the update's field, e.g. when the non-rigid part is set aside). InputError when the
/// transform is not linear.
DisplacementFieldImage::Pointer linearTransformField(const SpatialTransform& transform, const ImageGeometry& grid);

/// `moving` (a preoperative volume) resampled on the field's grid at y + d(y): linearly (no
/// clipping: statistics keep their sign and size), 0 outside.
ScalarImage::Pointer warpScalarVolume(const ScalarImage& moving, const DisplacementFieldImage& field);
/// The same by nearest neighbour, for label maps.
LabelImage::Pointer warpLabelVolume(const LabelImage& moving, const DisplacementFieldImage& field);

} // namespace brainshift
