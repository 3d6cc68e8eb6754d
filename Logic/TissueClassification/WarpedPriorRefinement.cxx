#include "WarpedPriorRefinement.h"

#include <stdexcept>

namespace brainshift {

MaskImage::Pointer regionMovedBySolve(const DisplacementFieldImage& field, const SpatialTransform& rigid, double movedMm,
                                      double reachMm)
{
  const AffineParameters r = affineParametersOf(&rigid);
  auto moved = MaskImage::New();
  moved->CopyInformation(&field);
  moved->SetRegions(field.GetLargestPossibleRegion());
  moved->Allocate();
  const auto size = field.GetLargestPossibleRegion().GetSize();
  const DisplacementVector* d = field.GetBufferPointer();
  unsigned char* m = moved->GetBufferPointer();
  std::size_t i = 0;
  for (std::size_t z = 0; z < size[2]; ++z) {
    for (std::size_t y = 0; y < size[1]; ++y) {
      for (std::size_t x = 0; x < size[0]; ++x, ++i) {
        PhysicalPoint p;
        field.TransformIndexToPhysicalPoint({{itk::IndexValueType(x), itk::IndexValueType(y), itk::IndexValueType(z)}}, p);
        double squared = 0;
        for (int a = 0; a < 3; ++a) {
          const double rigidA = r.translation[a] + r.matrix[a][0] * p[0] + r.matrix[a][1] * p[1] + r.matrix[a][2] * p[2];
          const double e = p[a] + d[i][a] - rigidA;
          squared += e * e;
        }
        m[i] = squared > movedMm * movedMm;
      }
    }
  }
  const ScalarImage::Pointer distance = signedDistanceMm(moved);
  const float* toMoved = distance->GetBufferPointer();
  for (std::size_t v = 0; v < i; ++v) m[v] = toMoved[v] <= float(reachMm);
  return moved;
}

std::size_t keepAnchorOutside(LabelImage& labels, const LabelImage& anchor, const MaskImage& region)
{
  const std::size_t n = labels.GetLargestPossibleRegion().GetNumberOfPixels();
  if (anchor.GetLargestPossibleRegion().GetNumberOfPixels() != n || region.GetLargestPossibleRegion().GetNumberOfPixels() != n) {
    throw std::invalid_argument("keepAnchorOutside: the labels, the anchor and the region are not on one grid");
  }
  const unsigned char* inside = region.GetBufferPointer();
  const LabelPixel* a = anchor.GetBufferPointer();
  LabelPixel* out = labels.GetBufferPointer();
  std::size_t changed = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!inside[i]) out[i] = a[i];
    else changed += out[i] != a[i];
  }
  return changed;
}

} // namespace brainshift
