// The intraoperative-to-preoperative field: under an affine displacement of the mesh the exact
// inverse is known, inside the mesh the field reproduces it; far outside it is the rigid transform;
// no folding; warping follows the field; a mesh without displacement is named.
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "DeformationField.h"
#include "LabelMapMesher.h"
#include "SyntheticData.h"

#include <itkImageRegionConstIteratorWithIndex.h>
#include <itkImageRegionIteratorWithIndex.h>
#include <vtkDoubleArray.h>
#include <vtkPointData.h>

#include <algorithm>
#include <cmath>
#include <iostream>

namespace {
using namespace brainshift;
using brainshift::testing::point;

// u(X) = A X + b, small enough not to fold.
const double A[3][3] = {{0.03, -0.01, 0.02}, {0.015, -0.02, 0.0}, {-0.01, 0.025, 0.01}};
const double b[3] = {1.0, -2.0, 0.5};

PhysicalPoint preopOf(const PhysicalPoint& p) // X with X + A X + b = p: (I + A)^-1 (p - b)
{
  double m[3][3], r[3];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m[i][j] = (i == j) + A[i][j];
    r[i] = p[unsigned(i)] - b[i];
  }
  const double det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                     m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  PhysicalPoint x;
  for (int c = 0; c < 3; ++c) { // Cramer's rule
    double mc[3][3];
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) mc[i][j] = j == c ? r[i] : m[i][j];
    }
    x[unsigned(c)] = (mc[0][0] * (mc[1][1] * mc[2][2] - mc[1][2] * mc[2][1]) - mc[0][1] * (mc[1][0] * mc[2][2] - mc[1][2] * mc[2][0]) +
                      mc[0][2] * (mc[1][0] * mc[2][1] - mc[1][1] * mc[2][0])) / det;
  }
  return x;
}

/// Where the solve put a tissue: the voxels the deformed tetrahedra of its label hold. Every
/// tetrahedron is brain here, so they are the voxels the field located in the mesh (`meshVoxels`);
/// well inside the displaced box all of them, outside it none; another label holds none.
void checkTissueWhereSolved(vtkUnstructuredGrid* mesh, const itk::Euler3DTransform<double>& rigid, const ImageGeometry& grid,
                            std::size_t meshVoxels)
{
  const MaskImage::Pointer brainWhereSolved = voxelsOfDeformedTissue(mesh, 2, rigid, grid, "mesh.vtu");
  BS_CHECK(ImageGeometry::of(brainWhereSolved.GetPointer()).sameGridAs(grid));
  std::size_t inMask = 0, wellInsideMissed = 0, outsideTaken = 0;
  itk::ImageRegionConstIteratorWithIndex<MaskImage> m(brainWhereSolved, brainWhereSolved->GetLargestPossibleRegion());
  for (; !m.IsAtEnd(); ++m) {
    PhysicalPoint y;
    brainWhereSolved->TransformIndexToPhysicalPoint(m.GetIndex(), y);
    const PhysicalPoint X = preopOf(rigid.TransformPoint(y));
    bool wellInside = true, outside = false;
    for (unsigned d = 0; d < 3; ++d) {
      wellInside = wellInside && X[d] > -18.5 && X[d] < 18.5;
      outside = outside || std::abs(X[d]) > 22.0; // the mesh's bounds: +-21.5 mm
    }
    inMask += m.Get();
    wellInsideMissed += wellInside && !m.Get();
    outsideTaken += outside && m.Get();
  }
  std::cout << "brain where solved: " << inMask << " voxels (" << meshVoxels << " located by the field)\n";
  BS_CHECK_MSG(inMask == meshVoxels, inMask);
  BS_CHECK_MSG(wellInsideMissed == 0, wellInsideMissed);
  BS_CHECK_MSG(outsideTaken == 0, outsideTaken);
  const MaskImage::Pointer noTumour = voxelsOfDeformedTissue(mesh, 4, rigid, grid, "mesh.vtu");
  BS_CHECK(std::count(noTumour->GetBufferPointer(), noTumour->GetBufferPointer() + grid.numberOfVoxels(), 1) == 0);
}
} // namespace

int DeformationFieldTest(int, char*[])
{
  return brainshift::testing::runTest("DeformationFieldTest", [] {
    // A 40 mm box of brain, meshed at 4 mm, displaced affinely.
    const ImageGeometry labelsGrid = brainshift::testing::grid({{40, 40, 40}}, {2.0, 2.0, 2.0}, point(-39, -39, -39));
    auto labels = brainshift::testing::makeImage<LabelImage>(labelsGrid);
    itk::ImageRegionIteratorWithIndex<LabelImage> it(labels, labels->GetLargestPossibleRegion());
    for (; !it.IsAtEnd(); ++it) {
      bool inside = true;
      for (int d = 0; d < 3; ++d) inside = inside && it.GetIndex()[d] >= 10 && it.GetIndex()[d] < 30;
      it.Set(inside ? 2 : 0);
    }
    MeshingParameters meshing;
    meshing.resolutionMm = 4.0;
    meshing.labels = {2};
    const LabelMapMesh mesh = meshLabelMap(*labels, meshing);
    vtkNew<vtkDoubleArray> displacement;
    displacement->SetName("Displacement");
    displacement->SetNumberOfComponents(3);
    for (vtkIdType i = 0; i < mesh.mesh->GetNumberOfPoints(); ++i) {
      double x[3], u[3];
      mesh.mesh->GetPoint(i, x);
      for (int r = 0; r < 3; ++r) u[r] = A[r][0] * x[0] + A[r][1] * x[1] + A[r][2] * x[2] + b[r];
      displacement->InsertNextTuple(u);
    }
    auto rigid = brainshift::testing::makeRigidTransform(); // intraop -> preop

    // The intraoperative grid: thick slices, another orientation, wider than the brain.
    const ImageGeometry grid = brainshift::testing::grid({{70, 70, 34}}, {1.5, 1.5, 3.0}, point(-45, -60, -40),
                                                         brainshift::testing::rotationAbout(0.3, -0.2, 1.0, 15.0));
    BS_CHECK_THROWS(intraopToPreopField(mesh.mesh, *rigid, grid, {}, "mesh.vtu"), InputError,
                    "mesh.vtu: no point array \"Displacement\"; run `brainshift simulate`");
    BS_CHECK_THROWS(voxelsOfDeformedTissue(mesh.mesh, 2, *rigid, grid, "mesh.vtu"), InputError,
                    "mesh.vtu: no point array \"Displacement\"; run `brainshift simulate`");
    mesh.mesh->GetPointData()->AddArray(displacement);
    const DeformationField f = intraopToPreopField(mesh.mesh, *rigid, grid, {}, "mesh.vtu");
    std::cout << f.voxels << " voxels, " << f.meshVoxels << " in the mesh, " << f.foldedVoxels << " folded, min Jacobian "
              << f.minimumJacobian << ", locate " << f.locateSeconds << " s\n";
    BS_CHECK(f.meshVoxels > 5000);
    BS_CHECK(f.foldedVoxels == 0);
    BS_CHECK(f.invertedDeformedTetrahedra == 0);
    BS_CHECK(f.minimumJacobian > 0.1); // the fade outside the mesh compresses, but does not fold

    // Inside the mesh: exact. Far outside: rigid.
    double worstInside = 0, worstFar = 0;
    std::size_t far = 0;
    itk::ImageRegionIteratorWithIndex<DisplacementFieldImage> field(f.field, f.field->GetLargestPossibleRegion());
    for (; !field.IsAtEnd(); ++field) {
      PhysicalPoint y;
      f.field->TransformIndexToPhysicalPoint(field.GetIndex(), y);
      PhysicalPoint x;
      for (unsigned d = 0; d < 3; ++d) x[d] = y[d] + field.Get()[d];
      const PhysicalPoint p = rigid->TransformPoint(y);
      const PhysicalPoint X = preopOf(p);
      bool inBox = true, farAway = false;
      for (unsigned d = 0; d < 3; ++d) {
        inBox = inBox && X[d] > -18.5 && X[d] < 18.5; // a little inside the meshed box [-19, 21]
        farAway = farAway || std::abs(p[d]) > 45.0;
      }
      if (inBox) worstInside = std::max(worstInside, x.EuclideanDistanceTo(X));
      if (farAway) {
        worstFar = std::max(worstFar, x.EuclideanDistanceTo(p));
        ++far;
      }
    }
    std::cout << "inside: worst " << worstInside << " mm; far outside (" << far << " voxels): worst " << worstFar << " mm\n";
    BS_CHECK_MSG(worstInside < 1e-3, worstInside); // the field is stored as float
    BS_CHECK(far > 100);
    BS_CHECK_MSG(worstFar < 0.05, worstFar);

    checkTissueWhereSolved(mesh.mesh, *rigid, grid, f.meshVoxels);

    // Warping: a preoperative ramp (value = its x coordinate) reads back X_x inside.
    const ImageGeometry preopGrid = brainshift::testing::grid({{60, 60, 60}}, {1.0, 1.0, 1.0}, point(-30, -30, -30));
    auto ramp = brainshift::testing::makeImage<ScalarImage>(preopGrid);
    itk::ImageRegionIteratorWithIndex<ScalarImage> r(ramp, ramp->GetLargestPossibleRegion());
    for (; !r.IsAtEnd(); ++r) {
      PhysicalPoint x;
      ramp->TransformIndexToPhysicalPoint(r.GetIndex(), x);
      r.Set(float(x[0]));
    }
    const ScalarImage::Pointer warped = warpScalarVolume(*ramp, *f.field);
    BS_CHECK(ImageGeometry::of(warped.GetPointer()).sameGridAs(grid));
    double worstRamp = 0;
    itk::ImageRegionIteratorWithIndex<ScalarImage> w(warped, warped->GetLargestPossibleRegion());
    for (; !w.IsAtEnd(); ++w) {
      PhysicalPoint y;
      warped->TransformIndexToPhysicalPoint(w.GetIndex(), y);
      const PhysicalPoint X = preopOf(rigid->TransformPoint(y));
      if (std::abs(X[0]) < 15 && std::abs(X[1]) < 15 && std::abs(X[2]) < 15) worstRamp = std::max(worstRamp, std::abs(w.Get() - X[0]));
    }
    std::cout << "warped ramp: worst " << worstRamp << " mm\n";
    BS_CHECK_MSG(worstRamp < 1e-3, worstRamp);
    const LabelImage::Pointer warpedLabels = warpLabelVolume(*labels, *f.field);
    std::size_t brain = 0;
    for (std::size_t i = 0; i < warpedLabels->GetLargestPossibleRegion().GetNumberOfPixels(); ++i) brain += warpedLabels->GetBufferPointer()[i] == 2;
    BS_CHECK(brain > 5000);
  });
}
