#include "SyntheticData.h"

#include <itkImageRegionIteratorWithIndex.h>
#include <itkVersor.h>

#include <cmath>
#include <random>

#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkDoubleArray.h>
#include <vtkFloatArray.h>
#include <vtkIntArray.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>

#include <cmath>
#include <initializer_list>

namespace brainshift::testing {
namespace {

vtkSmartPointer<vtkPoints> pointsOf(std::initializer_list<std::array<double, 3>> coordinates, int dataType = VTK_FLOAT)
{
  auto points = vtkSmartPointer<vtkPoints>::New();
  points->SetDataType(dataType);
  for (const auto& p : coordinates) points->InsertNextPoint(p[0], p[1], p[2]);
  return points;
}

vtkSmartPointer<vtkPolyData> surfaceOf(vtkPoints* points, std::initializer_list<std::array<vtkIdType, 3>> faces)
{
  vtkNew<vtkCellArray> triangles;
  for (const auto& face : faces) triangles->InsertNextCell(3, face.data());
  auto surface = vtkSmartPointer<vtkPolyData>::New();
  surface->SetPoints(points);
  surface->SetPolys(triangles);
  return surface;
}

} // namespace

PhysicalPoint point(double x, double y, double z)
{
  PhysicalPoint p;
  p[0] = x;
  p[1] = y;
  p[2] = z;
  return p;
}

ScalarImage::DirectionType rotationAbout(double x, double y, double z, double degrees)
{
  itk::Versor<double> rotation;
  itk::Versor<double>::VectorType axis;
  axis[0] = x;
  axis[1] = y;
  axis[2] = z;
  rotation.Set(axis, degrees * M_PI / 180.0);
  return rotation.GetMatrix();
}

ImageGeometry grid(const ScalarImage::SizeType& size, const std::array<double, 3>& spacing, const PhysicalPoint& origin,
                   const ScalarImage::DirectionType& direction)
{
  ImageGeometry geometry;
  geometry.size = size;
  for (unsigned i = 0; i < 3; ++i) geometry.spacing[i] = spacing[i];
  geometry.origin = origin;
  geometry.direction = direction;
  return geometry;
}

ScalarImage::Pointer makeUniformImage(const ScalarImage::SizeType& size, float value)
{
  auto image = makeImage<ScalarImage>(grid(size, {1.0, 1.0, 1.0}, point(0, 0, 0)));
  image->FillBuffer(value);
  return image;
}

DisplacementFieldImage::Pointer makeSmoothDisplacementField(const ImageGeometry& geometry, double zOffset)
{
  auto field = makeImage<DisplacementFieldImage>(geometry);
  itk::ImageRegionIteratorWithIndex<DisplacementFieldImage> it(field, field->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint p;
    field->TransformIndexToPhysicalPoint(it.GetIndex(), p);
    DisplacementVector d;
    d[0] = static_cast<float>(1.5 * std::sin(p[1] / 7.0));
    d[1] = static_cast<float>(-0.75 * std::cos(p[2] / 5.0));
    d[2] = static_cast<float>(0.05 * p[0] + zOffset);
    it.Set(d);
  }
  return field;
}

itk::Euler3DTransform<double>::Pointer makeRigidTransform()
{
  auto rigid = itk::Euler3DTransform<double>::New();
  rigid->SetCenter(point(10, -5, 20));
  rigid->SetRotation(0.1, -0.2, 0.3);
  itk::Euler3DTransform<double>::OutputVectorType translation;
  translation[0] = 5;
  translation[1] = -3;
  translation[2] = 2;
  rigid->SetTranslation(translation);
  return rigid;
}

vtkSmartPointer<vtkPolyData> makeTriangleSurface()
{
  const auto points = pointsOf({{1.5, -2.25, 3.0}, {40.125, 0.1, -7.0}, {-3.0, 55.5, 12.75}, {20.0, 30.0, 1.0 / 3.0}},
                               VTK_DOUBLE);
  auto surface = surfaceOf(points, {{0, 1, 2}, {1, 3, 2}});
  vtkNew<vtkDoubleArray> displacement;
  displacement->SetName("Displacement");
  displacement->SetNumberOfComponents(3);
  for (int i = 0; i < 4; ++i) displacement->InsertNextTuple3(0.5 * i, -0.25 * i, 1.0 / (i + 1));
  vtkNew<vtkIntArray> imposed;
  imposed->SetName("Imposed");
  imposed->InsertNextValue(1);
  imposed->InsertNextValue(0);
  surface->GetPointData()->AddArray(displacement);
  surface->GetCellData()->AddArray(imposed);
  return surface;
}

vtkSmartPointer<vtkPolyData> makeTetrahedronSurface()
{
  const auto points = pointsOf({{0, 0, 0}, {30.5, 0, 1}, {0, -25.25, 2}, {3, 4, 40.125}});
  auto surface = surfaceOf(points, {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}});
  vtkNew<vtkFloatArray> magnitude;
  magnitude->SetName("DisplacementMagnitude");
  for (float value : {0.0f, 1.5f, 3.25f, 4.75f}) magnitude->InsertNextValue(value);
  surface->GetPointData()->AddArray(magnitude);
  return surface;
}

vtkSmartPointer<vtkUnstructuredGrid> makeTwoTetrahedra()
{
  auto mesh = vtkSmartPointer<vtkUnstructuredGrid>::New();
  mesh->SetPoints(pointsOf({{0, 0, 0}, {10, 0, 0}, {0, 10, 0}, {0, 0, 10}, {10, 10, 10}}));
  const vtkIdType tets[2][4] = {{0, 1, 2, 3}, {1, 2, 3, 4}};
  for (const auto& tet : tets) mesh->InsertNextCell(VTK_TETRA, 4, tet);
  vtkNew<vtkIntArray> label;
  label->SetName("Label");
  label->InsertNextValue(2);
  label->InsertNextValue(4);
  mesh->GetCellData()->AddArray(label);
  return mesh;
}

itk::Image<unsigned char, 3>::Pointer makeRandomBallsMask(const std::array<double, 3>& spacing, double extentMm, int balls,
                                                          std::pair<double, double> centreMm, std::pair<double, double> radiusMm,
                                                          unsigned seed)
{
  using Mask = itk::Image<unsigned char, 3>;
  auto mask = Mask::New();
  Mask::SizeType size;
  Mask::SpacingType s;
  for (unsigned a = 0; a < 3; ++a) {
    size[a] = itk::SizeValueType(std::lround(extentMm / spacing[a]));
    s[a] = spacing[a];
  }
  mask->SetRegions(Mask::RegionType(size));
  mask->SetSpacing(s);
  mask->Allocate();
  mask->FillBuffer(0);
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> centre(centreMm.first, centreMm.second), radius(radiusMm.first, radiusMm.second);
  for (int ball = 0; ball < balls; ++ball) {
    const double c[3] = {centre(random), centre(random), centre(random)}, r = radius(random);
    for (itk::ImageRegionIteratorWithIndex<Mask> it(mask, mask->GetLargestPossibleRegion()); !it.IsAtEnd(); ++it) {
      double d2 = 0;
      for (unsigned a = 0; a < 3; ++a) d2 += std::pow(double(it.GetIndex()[a]) * spacing[a] - c[a], 2);
      if (d2 < r * r) it.Set(1);
    }
  }
  return mask;
}

} // namespace brainshift::testing
