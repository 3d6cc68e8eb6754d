#include "NodalFieldRasterisation.h"

#include "BrainShiftErrors.h"
#include "DeformationField.h"

#include <vtkCellType.h>
#include <vtkDataArray.h>
#include <vtkPointData.h>

#include <itk_eigen.h>
#include ITK_EIGEN(Dense)

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

namespace brainshift {
namespace {
using Vec = Eigen::Vector3d;
using Mat = Eigen::Matrix3d;
} // namespace

ScalarImage::Pointer rasteriseNodalScalar(vtkUnstructuredGrid* mesh, const std::string& arrayName, double spacingMm, float outside,
                                          const std::string& meshName)
{
  vtkDataArray* values = mesh ? mesh->GetPointData()->GetArray(arrayName.c_str()) : nullptr;
  if (!values) throw InputError(meshName + ": no point array \"" + arrayName + "\"");
  double bounds[6];
  mesh->GetBounds(bounds);
  ScalarImage::Pointer image = ScalarImage::New();
  ScalarImage::SizeType size;
  PhysicalPoint origin;
  ScalarImage::SpacingType spacing;
  for (int d = 0; d < 3; ++d) {
    origin[d] = bounds[2 * d] - spacingMm;
    spacing[d] = spacingMm;
    size[d] = itk::SizeValueType(std::ceil((bounds[2 * d + 1] - bounds[2 * d]) / spacingMm)) + 3;
  }
  image->SetOrigin(origin);
  image->SetSpacing(spacing);
  image->SetRegions(ScalarImage::RegionType(size));
  image->Allocate();
  image->FillBuffer(outside);
  float* voxels = image->GetBufferPointer();
  for (vtkIdType c = 0; c < mesh->GetNumberOfCells(); ++c) {
    if (mesh->GetCellType(c) != VTK_TETRA) throw InputError(meshName + ": cell " + std::to_string(c) + " is not a linear tetrahedron");
    const vtkIdType* ids = nullptr;
    vtkIdType count = 0;
    mesh->GetCellPoints(c, count, ids);
    std::array<Vec, 4> p;
    std::array<double, 4> v;
    for (int k = 0; k < 4; ++k) {
      mesh->GetPoint(ids[k], p[std::size_t(k)].data());
      v[std::size_t(k)] = values->GetComponent(ids[k], 0);
    }
    // Barycentric coordinates from the inverse of the edges (as DeformationField locates voxels).
    Mat edges;
    for (int k = 0; k < 3; ++k) edges.col(k) = p[std::size_t(k + 1)] - p[0];
    if (std::abs(edges.determinant()) < 1e-12) continue;
    const Mat inverse = edges.inverse();
    Vec lo = p[0], hi = p[0];
    for (int k = 1; k < 4; ++k) {
      lo = lo.cwiseMin(p[std::size_t(k)]);
      hi = hi.cwiseMax(p[std::size_t(k)]);
    }
    std::array<long, 3> low{}, high{};
    for (int d = 0; d < 3; ++d) {
      low[std::size_t(d)] = std::max(0L, long(std::ceil((lo[d] - origin[d]) / spacingMm)));
      high[std::size_t(d)] = std::min(long(size[d]) - 1, long(std::floor((hi[d] - origin[d]) / spacingMm)));
    }
    for (long z = low[2]; z <= high[2]; ++z)
      for (long y = low[1]; y <= high[1]; ++y)
        for (long x = low[0]; x <= high[0]; ++x) {
          const Vec q(origin[0] + double(x) * spacingMm, origin[1] + double(y) * spacingMm, origin[2] + double(z) * spacingMm);
          const Vec lambda = inverse * (q - p[0]);
          const double lambda0 = 1.0 - lambda.sum();
          constexpr double tolerance = -1e-9;
          if (lambda0 < tolerance || lambda[0] < tolerance || lambda[1] < tolerance || lambda[2] < tolerance) continue;
          voxels[std::size_t(x) + size[0] * (std::size_t(y) + size[1] * std::size_t(z))] =
            float(lambda0 * v[0] + lambda[0] * v[1] + lambda[1] * v[2] + lambda[2] * v[3]);
        }
  }
  return image;
}

ScalarImage::Pointer nodalScalarOnGrid(vtkUnstructuredGrid* mesh, const std::string& arrayName, const DisplacementFieldImage& field,
                                       double spacingMm, float outside, std::vector<float>* inside, const std::string& meshName)
{
  // NaN marks the voxels outside the mesh through the linear resampling; beyond the raster's grid
  // the resampling gives 0, which `outside` also replaces (the values are positive or NaN there).
  const ScalarImage::Pointer modelFrame =
    rasteriseNodalScalar(mesh, arrayName, spacingMm, std::numeric_limits<float>::quiet_NaN(), meshName);
  ScalarImage::Pointer onGrid = warpScalarVolume(*modelFrame, field);
  float* values = onGrid->GetBufferPointer();
  const std::size_t count = onGrid->GetLargestPossibleRegion().GetNumberOfPixels();
  if (inside) inside->clear();
  for (std::size_t i = 0; i < count; ++i) {
    const bool known = std::isfinite(values[i]) && values[i] != 0.0f;
    if (!known) values[i] = outside;
    else if (inside) inside->push_back(values[i]);
  }
  if (inside) std::sort(inside->begin(), inside->end());
  return onGrid;
}

} // namespace brainshift
