// A nodal scalar rasterised over a mesh: a linear field on two tetrahedra is reproduced exactly
// at every voxel inside them (linear interpolation is exact for it), voxels outside hold the
// outside value, and a mesh without the array is refused naming the mesh.
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "NodalFieldRasterisation.h"
#include "SyntheticData.h"

#include <vtkDoubleArray.h>
#include <vtkPointData.h>

#include <algorithm>
#include <cmath>
#include <iostream>

int NodalFieldRasterisationTest(int, char*[])
{
  return brainshift::testing::runTest("NodalFieldRasterisationTest", [] {
    using namespace brainshift;
    auto mesh = testing::makeTwoTetrahedra(); // points (0,0,0) (10,0,0) (0,10,0) (0,0,10) (10,10,10)
    auto linear = [](const double* p) { return 0.5 + 0.1 * p[0] - 0.05 * p[1] + 0.02 * p[2]; };
    vtkNew<vtkDoubleArray> values;
    values->SetName("Sigma");
    for (vtkIdType i = 0; i < mesh->GetNumberOfPoints(); ++i) values->InsertNextValue(linear(mesh->GetPoint(i)));
    mesh->GetPointData()->AddArray(values);
    const ScalarImage::Pointer image = rasteriseNodalScalar(mesh, "Sigma", 1.0, -1.0f, "two-tetrahedra.vtu");
    std::size_t inside = 0, outside = 0;
    double worst = 0;
    itk::ImageRegionConstIteratorWithIndex<ScalarImage> it(image, image->GetLargestPossibleRegion());
    for (; !it.IsAtEnd(); ++it) {
      PhysicalPoint p;
      image->TransformIndexToPhysicalPoint(it.GetIndex(), p);
      const double x[3] = {p[0], p[1], p[2]};
      if (it.Get() == -1.0f) {
        ++outside;
        continue;
      }
      ++inside;
      worst = std::max(worst, std::abs(double(it.Get()) - linear(x)));
    }
    std::cout << inside << " voxels inside, " << outside << " outside, largest error " << worst << '\n';
    // The two tetrahedra hold half the 10 mm cube: about half its 1,331 lattice points, faces included.
    BS_CHECK_MSG(inside > 550 && inside < 800, inside); // 671 measured
    BS_CHECK_MSG(worst < 1e-5, worst);
    // A point outside both (the cube's corner (10, 10, 0)) keeps the outside value.
    const ScalarImage::IndexType corner = image->TransformPhysicalPointToIndex(testing::point(10, 10, 0));
    BS_CHECK(image->GetPixel(corner) == -1.0f);
    // On a scan's grid through a field: here x = y + (1, 0, 0), so the voxel at y shows the value
    // at y + (1, 0, 0); voxels whose x leaves the mesh (or its last raster voxel) get the outside value.
    const ImageGeometry scan = testing::grid({{16, 16, 16}}, {1.0, 1.0, 1.0}, testing::point(-3, -3, -3));
    const auto field = testing::imageOn<DisplacementFieldImage>(scan, [](const PhysicalPoint&) {
      DisplacementVector d;
      d[0] = 1.0;
      d[1] = 0.0;
      d[2] = 0.0;
      return d;
    });
    std::vector<float> insideValues;
    const ScalarImage::Pointer onScan = nodalScalarOnGrid(mesh, "Sigma", *field, 1.0, -1.0f, &insideValues, "two-tetrahedra.vtu");
    const double deep[3] = {4.0, 3.0, 3.0}; // y = (3, 3, 3): x = (4, 3, 3), inside the first tetrahedron
    BS_CHECK_NEAR(double(onScan->GetPixel(onScan->TransformPhysicalPointToIndex(testing::point(3, 3, 3)))), linear(deep), 1e-5);
    BS_CHECK(onScan->GetPixel(onScan->TransformPhysicalPointToIndex(testing::point(-3, -3, -3))) == -1.0f);
    BS_CHECK_MSG(insideValues.size() > 100 && std::is_sorted(insideValues.begin(), insideValues.end()), insideValues.size());
    BS_CHECK_THROWS(rasteriseNodalScalar(mesh, "Missing", 1.0, 0.0f, "two-tetrahedra.vtu"), InputError,
                    "two-tetrahedra.vtu: no point array \"Missing\"");
  });
}
