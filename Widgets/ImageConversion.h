#pragma once
// Volumes of the scene as VTK images, and planar slices through them, in LPS millimetres.
//
// Coordinates: everything the views show and report is LPS mm, as ITK and the scene use (VTK has
// no anatomical convention of its own, so its world is simply taken to be LPS). A volume becomes
// a vtkImageData in its own scaled index frame (origin 0, the volume's spacing, no direction);
// the volume's origin and direction go into vtkImageReslice's axes, so oblique volumes slice right.
#include "ImageTypes.h"

#include <vtkImageData.h>
#include <vtkMatrix4x4.h>
#include <vtkSmartPointer.h>

#include <array>

namespace brainshift {

using Vector3 = std::array<double, 3>;

/// A rectangle of a plane in LPS: point (u, v) of the plane is u * axisU + v * axisV + offset * normal,
/// sampled at `spacing` from (originU, originV) over sizeU x sizeV pixels.
struct SlicePlane {
  Vector3 axisU{1, 0, 0}, axisV{0, 1, 0}, normal{0, 0, 1};
  double offset = 0;
  double originU = 0, originV = 0, spacing = 1;
  int sizeU = 1, sizeV = 1;

  PhysicalPoint pointAt(double u, double v) const;
  /// (u, v, offset) of an LPS point.
  Vector3 planeCoordinates(const PhysicalPoint& p) const;
};

/// A volume ready to be resliced: its voxels as vtkImageData and the map from LPS to its frame.
class ResliceableVolume {
public:
  ResliceableVolume() = default;
  explicit ResliceableVolume(const ScalarImage& image);
  explicit ResliceableVolume(const LabelImage& image);

  bool empty() const { return !data_; }
  /// The slice of the volume on `plane` (float scalars; NaN outside the volume). Labels are
  /// sampled at the nearest voxel, intensities linearly.
  vtkSmartPointer<vtkImageData> slice(const SlicePlane& plane) const;
  /// The LPS corners of the volume's bounding box (voxel centres).
  std::array<PhysicalPoint, 8> corners() const;
  double smallestSpacing() const;
  /// The smallest and largest voxel values.
  std::array<double, 2> scalarRange() const;

private:
  void setGeometry(const ImageGeometry& geometry);
  vtkSmartPointer<vtkImageData> data_;
  ImageGeometry geometry_;
  bool nearest_ = false;
};

} // namespace brainshift
