#include "LabelOverlap.h"

#include "DistanceMaps.h"

#include <cmath>
#include <stdexcept>

namespace brainshift {

namespace {

void requireSameGrid(const LabelImage& a, const LabelImage& b)
{
  if (!ImageGeometry::of(&a).sameGridAs(ImageGeometry::of(&b))) {
    throw std::invalid_argument("label maps on different grids: " + ImageGeometry::of(&a).describe() + " and " +
                                ImageGeometry::of(&b).describe());
  }
}

MaskImage::Pointer regionOf(const LabelImage& image, const std::set<LabelPixel>& labels)
{
  auto mask = MaskImage::New();
  mask->CopyInformation(&image);
  mask->SetRegions(image.GetLargestPossibleRegion());
  mask->Allocate();
  const std::size_t n = image.GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) mask->GetBufferPointer()[i] = labels.count(image.GetBufferPointer()[i]) ? 1 : 0;
  return mask;
}


/// Boundary voxels: in the region with a face neighbour outside it.
std::vector<std::size_t> boundaryVoxels(const MaskImage& region)
{
  const auto size = region.GetLargestPossibleRegion().GetSize();
  const unsigned char* m = region.GetBufferPointer();
  std::vector<std::size_t> boundary;
  for (std::size_t k = 0; k < size[2]; ++k) {
    for (std::size_t j = 0; j < size[1]; ++j) {
      for (std::size_t i = 0; i < size[0]; ++i) {
        const std::size_t o = i + size[0] * (j + size[1] * k);
        if (!m[o]) continue;
        const bool edge = i == 0 || j == 0 || k == 0 || i + 1 == size[0] || j + 1 == size[1] || k + 1 == size[2] ||
                          !m[o - 1] || !m[o + 1] || !m[o - size[0]] || !m[o + size[0]] ||
                          !m[o - size[0] * size[1]] || !m[o + size[0] * size[1]];
        if (edge) boundary.push_back(o);
      }
    }
  }
  return boundary;
}
} // namespace

double diceCoefficient(const LabelImage& a, const LabelImage& b, const std::set<LabelPixel>& labels)
{
  requireSameGrid(a, b);
  std::size_t inA = 0, inB = 0, both = 0;
  const std::size_t n = a.GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) {
    const bool x = labels.count(a.GetBufferPointer()[i]) > 0, y = labels.count(b.GetBufferPointer()[i]) > 0;
    inA += x;
    inB += y;
    both += x && y;
  }
  return inA + inB == 0 ? 1.0 : 2.0 * double(both) / double(inA + inB);
}

double meanSurfaceDistanceMm(const LabelImage& a, const LabelImage& b, const std::set<LabelPixel>& labels)
{
  requireSameGrid(a, b);
  const MaskImage::Pointer regionA = regionOf(a, labels), regionB = regionOf(b, labels);
  const ScalarImage::Pointer toA = signedDistanceMm(regionA), toB = signedDistanceMm(regionB);
  const std::vector<std::size_t> boundaryA = boundaryVoxels(*regionA), boundaryB = boundaryVoxels(*regionB);
  if (boundaryA.empty() || boundaryB.empty()) return std::numeric_limits<double>::infinity();
  // The signed distance at a boundary voxel of the other region is its distance to this region's
  // boundary (Maurer measures to the boundary between voxel centres: within half a voxel).
  double sum = 0;
  for (std::size_t o : boundaryA) sum += std::abs(toB->GetBufferPointer()[o]);
  for (std::size_t o : boundaryB) sum += std::abs(toA->GetBufferPointer()[o]);
  return sum / double(boundaryA.size() + boundaryB.size());
}

} // namespace brainshift
