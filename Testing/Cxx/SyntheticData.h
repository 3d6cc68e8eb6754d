#pragma once
// Small synthetic data for the tests: points, image grids, surfaces, meshes and transforms with
// fixed values. Tests assert against these values, so change one only together with its tests.
#include "ImageTypes.h"
#include "TransformIO.h"

#include <itkEuler3DTransform.h>
#include <itkImageRegionIteratorWithIndex.h>
#include <vtkPolyData.h>
#include <vtkSmartPointer.h>
#include <vtkUnstructuredGrid.h>

#include <array>
#include <utility>

namespace brainshift::testing {

/// The point (x, y, z), LPS mm.
PhysicalPoint point(double x, double y, double z);

/// The rotation by `degrees` about the axis (x, y, z) (any length), as an image direction.
ScalarImage::DirectionType rotationAbout(double x, double y, double z, double degrees);

/// The grid of `size` voxels of `spacing` mm, first voxel at `origin`, axes along `direction`.
ImageGeometry grid(const ScalarImage::SizeType& size, const std::array<double, 3>& spacing, const PhysicalPoint& origin,
                   const ScalarImage::DirectionType& direction = ScalarImage::DirectionType::GetIdentity());

/// An allocated, uninitialised image of any pixel type on `geometry`.
template <class TImage>
typename TImage::Pointer makeImage(const ImageGeometry& geometry)
{
  return geometry.allocate<TImage>();
}

/// An image on `geometry` whose voxel at physical point p holds `value(p)`.
template <class TImage, class Value>
typename TImage::Pointer imageOn(const ImageGeometry& geometry, Value value)
{
  auto image = geometry.allocate<TImage>();
  itk::ImageRegionIteratorWithIndex<TImage> it(image, image->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint p;
    image->TransformIndexToPhysicalPoint(it.GetIndex(), p);
    it.Set(value(p));
  }
  return image;
}

/// An image of `size` voxels of 1 mm at the origin, axis-aligned, every voxel `value`.
ScalarImage::Pointer makeUniformImage(const ScalarImage::SizeType& size, float value);

/// The field d(p) = (1.5 sin(p_y / 7), -0.75 cos(p_z / 5), 0.05 p_x + zOffset) mm sampled on `geometry`.
DisplacementFieldImage::Pointer makeSmoothDisplacementField(const ImageGeometry& geometry, double zOffset = 0.0);

/// A rigid transform: Euler angles (0.1, -0.2, 0.3) rad about the centre (10, -5, 20), translation (5, -3, 2).
itk::Euler3DTransform<double>::Pointer makeRigidTransform();

/// Two triangles on four double-precision points, a 3-component point array "Displacement" and a cell array "Imposed".
vtkSmartPointer<vtkPolyData> makeTriangleSurface();

/// A tetrahedron's closed surface (four triangles), with a float point array "DisplacementMagnitude".
vtkSmartPointer<vtkPolyData> makeTetrahedronSurface();

/// Two tetrahedra sharing a face (five points), with an int cell array "Label" (2, 4).
vtkSmartPointer<vtkUnstructuredGrid> makeTwoTetrahedra();

/// A binary mask (1 inside) of `balls` random overlapping balls (seeded): concave and convex
/// boundaries, thin bridges. The grid spans `extentMm` along each axis from the origin at `spacing`;
/// centres are drawn in [centreMm.first, centreMm.second] per axis, radii in [radiusMm.first,
/// radiusMm.second].
itk::Image<unsigned char, 3>::Pointer makeRandomBallsMask(const std::array<double, 3>& spacing, double extentMm, int balls,
                                                          std::pair<double, double> centreMm, std::pair<double, double> radiusMm,
                                                          unsigned seed);

} // namespace brainshift::testing
