#include "NodalFieldRasterisation.h"

#include "BrainShiftErrors.h"

#include <vtkCellType.h>
#include <vtkDataArray.h>
#include <vtkPointData.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace brainshift {

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
    std::array<std::array<double, 3>, 4> p;
    std::array<double, 4> v;
    for (int k = 0; k < 4; ++k) {
      mesh->GetPoint(ids[k], p[std::size_t(k)].data());
      v[std::size_t(k)] = values->GetComponent(ids[k], 0);
    }
    // Barycentric coordinates from the inverse of [p1 - p0, p2 - p0, p3 - p0].
    double m[3][3];
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) m[r][k] = p[std::size_t(k + 1)][std::size_t(r)] - p[0][std::size_t(r)];
    const double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                       m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if (std::abs(det) < 1e-12) continue;
    double inv[3][3];
    inv[0][0] = (m[1][1] * m[2][2] - m[1][2] * m[2][1]) / det;
    inv[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) / det;
    inv[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) / det;
    inv[1][0] = (m[1][2] * m[2][0] - m[1][0] * m[2][2]) / det;
    inv[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) / det;
    inv[1][2] = (m[0][2] * m[1][0] - m[0][0] * m[1][2]) / det;
    inv[2][0] = (m[1][0] * m[2][1] - m[1][1] * m[2][0]) / det;
    inv[2][1] = (m[0][1] * m[2][0] - m[0][0] * m[2][1]) / det;
    inv[2][2] = (m[0][0] * m[1][1] - m[0][1] * m[1][0]) / det;
    std::array<long, 3> low{}, high{};
    for (int d = 0; d < 3; ++d) {
      double lo = p[0][std::size_t(d)], hi = lo;
      for (int k = 1; k < 4; ++k) {
        lo = std::min(lo, p[std::size_t(k)][std::size_t(d)]);
        hi = std::max(hi, p[std::size_t(k)][std::size_t(d)]);
      }
      low[std::size_t(d)] = std::max(0L, long(std::ceil((lo - origin[d]) / spacingMm)));
      high[std::size_t(d)] = std::min(long(size[d]) - 1, long(std::floor((hi - origin[d]) / spacingMm)));
    }
    for (long z = low[2]; z <= high[2]; ++z)
      for (long y = low[1]; y <= high[1]; ++y)
        for (long x = low[0]; x <= high[0]; ++x) {
          const double q[3] = {origin[0] + x * spacingMm - p[0][0], origin[1] + y * spacingMm - p[0][1], origin[2] + z * spacingMm - p[0][2]};
          double l[4];
          l[1] = inv[0][0] * q[0] + inv[0][1] * q[1] + inv[0][2] * q[2];
          l[2] = inv[1][0] * q[0] + inv[1][1] * q[1] + inv[1][2] * q[2];
          l[3] = inv[2][0] * q[0] + inv[2][1] * q[1] + inv[2][2] * q[2];
          l[0] = 1 - l[1] - l[2] - l[3];
          constexpr double tolerance = -1e-9;
          if (l[0] < tolerance || l[1] < tolerance || l[2] < tolerance || l[3] < tolerance) continue;
          voxels[std::size_t(x) + size[0] * (std::size_t(y) + size[1] * std::size_t(z))] =
            float(l[0] * v[0] + l[1] * v[1] + l[2] * v[2] + l[3] * v[3]);
        }
  }
  return image;
}

} // namespace brainshift
