// linearlyResampled and nearestResampled against ITK's ResampleImageFilter with its linear and
// nearest-neighbour interpolators: an oblique, anisotropic image resampled onto a grid that
// overhangs it on every side (the edge's half voxel, the outside's 0), through the identity, a
// rigid transform and a non-uniform affine one. Linear: every voxel within 1e-4 of the filter's
// (the continuous index is computed per voxel where the filter accumulates it along a row), the
// same voxels inside. Nearest: the same label at every voxel but where the continuous index lies
// within 1e-6 of a half (rounding may go either way there), and those few. A transform that is not
// linear is refused. linearlyWarped and nearestWarped against ITK's WarpImageFilter the same way,
// through a smooth field of up to 6 mm that carries part of the grid outside the image.
#include "AffineResampling.h"
#include "BrainShiftTestingSupport.h"
#include "SyntheticData.h"

#include <itkAffineTransform.h>
#include <itkDisplacementFieldTransform.h>
#include <itkIdentityTransform.h>
#include <itkLinearInterpolateImageFunction.h>
#include <itkNearestNeighborInterpolateImageFunction.h>
#include <itkResampleImageFilter.h>
#include <itkWarpImageFilter.h>

#include <cmath>
#include <iostream>

namespace {
using namespace brainshift;

template <class Image, class Interpolator>
typename Image::Pointer itkResampled(const Image& image, const ImageGeometry& grid, const SpatialTransform* transform)
{
  auto filter = itk::ResampleImageFilter<Image, Image, double>::New();
  filter->SetInput(&image);
  filter->SetInterpolator(Interpolator::New());
  if (transform) {
    filter->SetTransform(transform);
  } else {
    filter->SetTransform(itk::IdentityTransform<double, 3>::New());
  }
  filter->SetOutputOrigin(grid.origin);
  filter->SetOutputSpacing(grid.spacing);
  filter->SetOutputDirection(grid.direction);
  filter->SetSize(grid.size);
  filter->SetDefaultPixelValue(0);
  filter->Update();
  return filter->GetOutput();
}

/// How far the voxel's continuous index in `image` lies from a half on its nearest axis.
template <class Image>
double distanceFromHalf(const Image& image, const ImageGeometry& grid, const SpatialTransform* transform, std::size_t voxel)
{
  const std::size_t i = voxel % grid.size[0], j = (voxel / grid.size[0]) % grid.size[1], k = voxel / (grid.size[0] * grid.size[1]);
  PhysicalPoint p;
  for (unsigned r = 0; r < 3; ++r) {
    p[r] = grid.origin[r];
    const double index[3] = {double(i), double(j), double(k)};
    for (unsigned c = 0; c < 3; ++c) p[r] += grid.direction(r, c) * grid.spacing[c] * index[c];
  }
  if (transform) p = transform->TransformPoint(p);
  const auto c = image.template TransformPhysicalPointToContinuousIndex<double>(p);
  double nearest = 1;
  for (int a = 0; a < 3; ++a) nearest = std::min(nearest, std::abs(c[a] - std::floor(c[a]) - 0.5));
  return nearest;
}

template <class Image, class Interpolator>
typename Image::Pointer itkWarped(const Image& image, const DisplacementFieldImage& field)
{
  auto filter = itk::WarpImageFilter<Image, Image, DisplacementFieldImage>::New();
  filter->SetInput(&image);
  filter->SetDisplacementField(&field);
  filter->SetInterpolator(Interpolator::New());
  filter->SetOutputParametersFromImage(&field);
  filter->SetEdgePaddingValue(0);
  filter->Update();
  return filter->GetOutput();
}

/// The grid's voxel's continuous index in `image`, at its point moved by the field.
template <class Image>
double warpedDistanceFromHalf(const Image& image, const DisplacementFieldImage& field, std::size_t voxel)
{
  const auto size = field.GetLargestPossibleRegion().GetSize();
  const itk::Index<3> index = {{itk::IndexValueType(voxel % size[0]), itk::IndexValueType((voxel / size[0]) % size[1]),
                                itk::IndexValueType(voxel / (size[0] * size[1]))}};
  PhysicalPoint p;
  field.TransformIndexToPhysicalPoint(index, p);
  for (unsigned r = 0; r < 3; ++r) p[r] += field.GetBufferPointer()[voxel][r];
  const auto c = image.template TransformPhysicalPointToContinuousIndex<double>(p);
  double nearest = 1;
  for (int a = 0; a < 3; ++a) nearest = std::min(nearest, std::abs(c[a] - std::floor(c[a]) - 0.5));
  return nearest;
}

/// Our values against the filter's over the grid: linear within 1e-4, the same voxels inside, the
/// same labels but where the continuous index lies within 1e-6 of a half (`nearHalf`), and those few.
template <class NearHalf>
void compareValues(const std::vector<float>& linear, const ScalarImage& expected, const std::vector<LabelPixel>& nearest,
                   const LabelImage& expectedLabels, std::size_t n, NearHalf nearHalf, const char* name)
{
  BS_CHECK_MSG(linear.size() == n && nearest.size() == n, linear.size() << " " << nearest.size() << " of " << n);
  double largest = 0;
  std::size_t inside = 0, insideOnlyOne = 0, labelsDiffer = 0, labelsAtHalf = 0;
  for (std::size_t v = 0; v < n; ++v) {
    const float e = expected.GetBufferPointer()[v];
    largest = std::max(largest, double(std::abs(linear[v] - e)));
    inside += e != 0;
    insideOnlyOne += (e != 0) != (linear[v] != 0);
    if (nearest[v] != expectedLabels.GetBufferPointer()[v]) {
      ++labelsDiffer;
      labelsAtHalf += nearHalf(v);
    }
  }
  std::cout << name << ": " << n << " voxels, " << inside << " inside; linear largest difference " << largest << ", inside for one only "
            << insideOnlyOne << "; labels differ at " << labelsDiffer << " (" << labelsAtHalf << " at a half)\n";
  BS_CHECK_MSG(inside > n / 4 && inside < n, inside);
  BS_CHECK_MSG(largest < 1e-4, largest);
  BS_CHECK_MSG(insideOnlyOne == 0, insideOnlyOne);
  BS_CHECK_MSG(labelsDiffer == labelsAtHalf, labelsDiffer << " differ, " << labelsAtHalf << " at a half");
  BS_CHECK_MSG(labelsDiffer <= n / 10000, labelsDiffer);
}

void compareWarped(const ScalarImage& image, const LabelImage& labels, const DisplacementFieldImage& field)
{
  const ScalarImage::Pointer expected = itkWarped<ScalarImage, itk::LinearInterpolateImageFunction<ScalarImage, double>>(image, field);
  const LabelImage::Pointer expectedLabels = itkWarped<LabelImage, itk::NearestNeighborInterpolateImageFunction<LabelImage, double>>(labels, field);
  compareValues(linearlyWarped(image, field), *expected, nearestWarped(labels, field), *expectedLabels,
                field.GetLargestPossibleRegion().GetNumberOfPixels(),
                [&](std::size_t v) { return warpedDistanceFromHalf(labels, field, v) < 1e-6; }, "warped");
}

void compare(const ScalarImage& image, const LabelImage& labels, const ImageGeometry& grid, const SpatialTransform* transform, const char* name)
{
  const ScalarImage::Pointer expected = itkResampled<ScalarImage, itk::LinearInterpolateImageFunction<ScalarImage, double>>(image, grid, transform);
  const LabelImage::Pointer expectedLabels =
    itkResampled<LabelImage, itk::NearestNeighborInterpolateImageFunction<LabelImage, double>>(labels, grid, transform);
  compareValues(linearlyResampled(image, grid, transform), *expected, nearestResampled(labels, grid, transform), *expectedLabels,
                grid.numberOfVoxels(), [&](std::size_t v) { return distanceFromHalf(labels, grid, transform, v) < 1e-6; }, name);
}
} // namespace

int AffineResamplingTest(int, char*[])
{
  return testing::runTest("AffineResamplingTest", [] {
    // An oblique anisotropic image with texture and a few labels (values ~100, steps of 1 in the label).
    const ImageGeometry imageGrid =
      testing::grid({{40, 36, 22}}, {1.1, 0.9, 2.5}, testing::point(-21, -17, -26), testing::rotationAbout(0.3, -0.5, 1.0, 17));
    const ScalarImage::Pointer image = testing::imageOn<ScalarImage>(imageGrid, [](const PhysicalPoint& p) {
      return float(100 + 20 * std::sin(0.31 * p[0] + 0.7) * std::cos(0.23 * p[1] - 0.2) + 0.5 * p[2]);
    });
    const LabelImage::Pointer labels = testing::imageOn<LabelImage>(imageGrid, [](const PhysicalPoint& p) {
      return LabelPixel(1 + int(std::floor(0.13 * p[0] + 0.07 * p[1] - 0.11 * p[2] + 20)) % 5);
    });
    // The grid: axis-aligned, another spacing, overhanging the image on every side.
    const ImageGeometry onto = testing::grid({{62, 58, 50}}, {0.9, 1.0, 1.2}, testing::point(-30, -29, -31));
    compare(*image, *labels, onto, nullptr, "identity");

    const auto rigid = testing::makeRigidTransform(); // 0.1, -0.2, 0.3 rad about (10, -5, 20), moved (5, -3, 2)
    compare(*image, *labels, onto, rigid.GetPointer(), "rigid");

    auto affine = itk::AffineTransform<double, 3>::New();
    itk::AffineTransform<double, 3>::MatrixType m;
    m(0, 0) = 1.1, m(0, 1) = 0.05, m(0, 2) = -0.02;
    m(1, 0) = -0.04, m(1, 1) = 0.93, m(1, 2) = 0.06;
    m(2, 0) = 0.03, m(2, 1) = -0.01, m(2, 2) = 1.05;
    affine->SetMatrix(m);
    itk::AffineTransform<double, 3>::OutputVectorType t;
    t[0] = 1.7;
    t[1] = -2.3;
    t[2] = 0.9;
    affine->SetTranslation(t);
    compare(*image, *labels, onto, affine.GetPointer(), "affine");

    // The grid of the image itself: every voxel its own value, exactly.
    const std::vector<float> same = linearlyResampled(*image, imageGrid, nullptr);
    std::size_t unequal = 0;
    for (std::size_t v = 0; v < same.size(); ++v) unequal += same[v] != image->GetBufferPointer()[v];
    BS_CHECK_MSG(unequal == 0, unequal);

    auto field = itk::DisplacementFieldTransform<double, 3>::New();
    BS_CHECK_THROWS(linearlyResampled(*image, onto, field.GetPointer()), std::invalid_argument, "not linear");

    // Through a displacement field on an oblique grid of its own: smooth, up to 6 mm, so that
    // part of the grid lands outside the image and part of the outside lands in it.
    const ImageGeometry fieldGrid =
      testing::grid({{48, 44, 30}}, {1.0, 1.1, 1.6}, testing::point(-27, -24, -28), testing::rotationAbout(-0.2, 0.4, 1.0, 9));
    const DisplacementFieldImage::Pointer displacement = fieldGrid.allocate<DisplacementFieldImage>();
    for (std::size_t v = 0, n = fieldGrid.numberOfVoxels(); v < n; ++v) {
      const itk::Index<3> index = {{itk::IndexValueType(v % fieldGrid.size[0]), itk::IndexValueType((v / fieldGrid.size[0]) % fieldGrid.size[1]),
                                    itk::IndexValueType(v / (fieldGrid.size[0] * fieldGrid.size[1]))}};
      PhysicalPoint p;
      displacement->TransformIndexToPhysicalPoint(index, p);
      DisplacementVector& d = displacement->GetBufferPointer()[v];
      d[0] = float(6 * std::sin(0.11 * p[1] + 0.3));
      d[1] = float(4 * std::cos(0.09 * p[2] - 0.1) - 1.5);
      d[2] = float(3 * std::sin(0.07 * p[0]) + 0.25 * std::cos(0.2 * p[1]));
    }
    compareWarped(*image, *labels, *displacement);
    // A zero field on the image's own grid: every voxel its own value and label.
    const DisplacementFieldImage::Pointer zero = imageGrid.allocate<DisplacementFieldImage>();
    zero->FillBuffer(DisplacementVector(0.0f));
    const std::vector<float> unmoved = linearlyWarped(*image, *zero);
    const std::vector<LabelPixel> unmovedLabels = nearestWarped(*labels, *zero);
    std::size_t moved = 0;
    for (std::size_t v = 0; v < unmoved.size(); ++v) {
      moved += unmoved[v] != image->GetBufferPointer()[v] || unmovedLabels[v] != labels->GetBufferPointer()[v];
    }
    BS_CHECK_MSG(moved == 0, moved);
    BS_CHECK_THROWS(linearlyWarped(*image, *DisplacementFieldImage::New()), std::invalid_argument, "no whole buffer");
    BS_CHECK_THROWS(linearlyWarped(*ScalarImage::New(), *zero), std::invalid_argument, "no whole buffer");
  });
}
