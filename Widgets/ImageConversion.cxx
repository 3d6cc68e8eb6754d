#include "ImageConversion.h"

#include <vtkFloatArray.h>
#include <vtkImageReslice.h>
#include <vtkPointData.h>
#include <vtkUnsignedShortArray.h>

#include <algorithm>
#include <cstring>
#include <limits>

namespace brainshift {

PhysicalPoint SlicePlane::pointAt(double u, double v) const
{
  PhysicalPoint p;
  for (int i = 0; i < 3; ++i) p[i] = u * axisU[i] + v * axisV[i] + offset * normal[i];
  return p;
}

Vector3 SlicePlane::planeCoordinates(const PhysicalPoint& p) const
{
  auto dot = [&p](const Vector3& a) { return a[0] * p[0] + a[1] * p[1] + a[2] * p[2]; };
  return {dot(axisU), dot(axisV), dot(normal)};
}

namespace {
template <class TImage, class TArray>
vtkSmartPointer<vtkImageData> copyVoxels(const TImage& image)
{
  const auto size = image.GetLargestPossibleRegion().GetSize();
  auto data = vtkSmartPointer<vtkImageData>::New();
  data->SetDimensions(int(size[0]), int(size[1]), int(size[2]));
  data->SetSpacing(image.GetSpacing()[0], image.GetSpacing()[1], image.GetSpacing()[2]);
  data->SetOrigin(0, 0, 0);
  auto voxels = vtkSmartPointer<TArray>::New();
  const vtkIdType count = vtkIdType(size[0] * size[1] * size[2]);
  voxels->SetNumberOfValues(count);
  std::memcpy(voxels->GetPointer(0), image.GetBufferPointer(), sizeof(typename TImage::PixelType) * std::size_t(count));
  data->GetPointData()->SetScalars(voxels);
  return data;
}
} // namespace

ResliceableVolume::ResliceableVolume(const ScalarImage& image)
  : data_(copyVoxels<ScalarImage, vtkFloatArray>(image))
{
  setGeometry(ImageGeometry::of(&image));
}

ResliceableVolume::ResliceableVolume(const LabelImage& image)
  : data_(copyVoxels<LabelImage, vtkUnsignedShortArray>(image))
  , nearest_(true)
{
  setGeometry(ImageGeometry::of(&image));
}

void ResliceableVolume::setGeometry(const ImageGeometry& geometry)
{
  geometry_ = geometry;
}

double ResliceableVolume::smallestSpacing() const
{
  return std::min({geometry_.spacing[0], geometry_.spacing[1], geometry_.spacing[2]});
}

std::array<double, 2> ResliceableVolume::scalarRange() const
{
  double range[2] = {0, 1};
  data_->GetScalarRange(range);
  return {range[0], range[1]};
}

std::array<PhysicalPoint, 8> ResliceableVolume::corners() const
{
  std::array<PhysicalPoint, 8> corners;
  for (int c = 0; c < 8; ++c) {
    itk::Vector<double, 3> scaledIndex;
    for (int a = 0; a < 3; ++a) scaledIndex[a] = ((c >> a) & 1) ? double(geometry_.size[a] - 1) * geometry_.spacing[a] : 0.0;
    corners[c] = geometry_.origin + geometry_.direction * scaledIndex;
  }
  return corners;
}

vtkSmartPointer<vtkImageData> ResliceableVolume::slice(const SlicePlane& plane) const
{
  // Reslice axes: output (u, v, 0) -> the volume's scaled index frame D^-1 (p - origin).
  const auto inverse = geometry_.direction.GetInverse();
  auto toFrame = [&inverse](const Vector3& v) {
    Vector3 r{};
    for (int i = 0; i < 3; ++i) r[i] = inverse[i][0] * v[0] + inverse[i][1] * v[1] + inverse[i][2] * v[2];
    return r;
  };
  Vector3 offsetPoint{};
  for (int i = 0; i < 3; ++i) offsetPoint[i] = plane.offset * plane.normal[i] - geometry_.origin[i];
  const Vector3 columns[4] = {toFrame(plane.axisU), toFrame(plane.axisV), toFrame(plane.normal), toFrame(offsetPoint)};
  auto axes = vtkSmartPointer<vtkMatrix4x4>::New();
  for (int column = 0; column < 4; ++column) {
    for (int row = 0; row < 3; ++row) axes->SetElement(row, column, columns[column][row]);
  }

  vtkNew<vtkImageReslice> reslice;
  reslice->SetInputData(data_);
  reslice->SetResliceAxes(axes);
  reslice->SetOutputDimensionality(2);
  reslice->SetOutputOrigin(plane.originU, plane.originV, 0.0);
  reslice->SetOutputSpacing(plane.spacing, plane.spacing, 1.0);
  reslice->SetOutputExtent(0, plane.sizeU - 1, 0, plane.sizeV - 1, 0, 0);
  reslice->SetOutputScalarType(VTK_FLOAT);
  reslice->SetBackgroundLevel(std::numeric_limits<double>::quiet_NaN());
  if (nearest_) reslice->SetInterpolationModeToNearestNeighbor();
  else reslice->SetInterpolationModeToLinear();
  reslice->Update();
  vtkSmartPointer<vtkImageData> slice = reslice->GetOutput();
  return slice;
}

} // namespace brainshift
