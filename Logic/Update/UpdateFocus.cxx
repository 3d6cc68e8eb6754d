#include "UpdateFocus.h"

#include <itkImageRegionConstIteratorWithIndex.h>

#include <cmath>

namespace brainshift {

namespace {
/// The voxel of the strongest finite |value| of `image`, as an LPS point; none when no voxel is finite.
std::optional<std::array<double, 3>> strongestVoxel(const ScalarImage& image)
{
  itk::ImageRegionConstIteratorWithIndex<ScalarImage> it(&image, image.GetLargestPossibleRegion());
  std::optional<ScalarImage::IndexType> best;
  float strongest = -1;
  for (; !it.IsAtEnd(); ++it) {
    const float magnitude = std::fabs(it.Get());
    if (std::isfinite(magnitude) && magnitude > strongest) {
      strongest = magnitude;
      best = it.GetIndex();
    }
  }
  if (!best) return std::nullopt;
  ScalarImage::PointType point;
  image.TransformIndexToPhysicalPoint(*best, point);
  return std::array<double, 3>{point[0], point[1], point[2]};
}

/// The centroid of `label` in `labels`, as an LPS point; none when the label is absent.
std::optional<std::array<double, 3>> labelCentroid(const LabelImage& labels, LabelPixel label)
{
  itk::ImageRegionConstIteratorWithIndex<LabelImage> it(&labels, labels.GetLargestPossibleRegion());
  std::array<double, 3> sum{0, 0, 0};
  std::size_t count = 0;
  for (; !it.IsAtEnd(); ++it) {
    if (it.Get() != label) continue;
    LabelImage::PointType point;
    labels.TransformIndexToPhysicalPoint(it.GetIndex(), point);
    for (int d = 0; d < 3; ++d) sum[std::size_t(d)] += point[d];
    ++count;
  }
  if (count == 0) return std::nullopt;
  for (double& s : sum) s /= double(count);
  return sum;
}
} // namespace

std::optional<std::array<double, 3>> updateFocusPoint(const Scene& scene)
{
  for (const auto& volume : scene.nodesOfType<ScalarVolumeNode>()) {
    if (volume->role() == "overlay" && volume->name() != DisplacementUncertaintyNodeName && volume->image()) {
      if (auto peak = strongestVoxel(*volume->image())) return peak;
    }
  }
  const auto labels = scene.findByName<LabelMapVolumeNode>("warped preop labels");
  if (labels && labels->image()) return labelCentroid(*labels->image(), 4);
  return std::nullopt;
}

} // namespace brainshift
