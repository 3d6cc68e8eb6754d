#pragma once
// A scalar of a tetrahedral mesh's nodes (e.g. the solve's "DisplacementUncertainty") as an image
// over the mesh, in the mesh's frame: each voxel inside a tetrahedron takes the barycentric
// interpolation of its nodes' values, the others `outside`. Rasterised tetrahedron by tetrahedron
// (each over the voxels of its bounding box), so its cost follows the mesh, not the image.
#include "ImageTypes.h"

#include <vector>

#include <vtkUnstructuredGrid.h>

#include <string>

namespace brainshift {

/// An axis-aligned grid of `spacingMm` over the mesh's bounds (and one voxel more). InputError
/// naming `meshName` when the mesh lacks the point array or holds other cells than tetrahedra.
ScalarImage::Pointer rasteriseNodalScalar(vtkUnstructuredGrid* mesh, const std::string& arrayName, double spacingMm, float outside,
                                          const std::string& meshName = "the mesh");

/// The nodal scalar on the intraoperative grid of `field` (x = y + d(y), preoperative frame): each
/// voxel takes the value at x, interpolated in the undeformed mesh (rasterised at `spacingMm` and
/// resampled linearly). Voxels whose x falls outside the mesh, or within a raster voxel of its
/// boundary, get `outside`; `inside` (if given) receives the other voxels' values, sorted.
ScalarImage::Pointer nodalScalarOnGrid(vtkUnstructuredGrid* mesh, const std::string& arrayName, const DisplacementFieldImage& field,
                                       double spacingMm, float outside, std::vector<float>* inside = nullptr,
                                       const std::string& meshName = "the mesh");

} // namespace brainshift
