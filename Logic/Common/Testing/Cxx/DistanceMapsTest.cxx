// voxelsAtLeastDeep and voxelsWithin (the morphology without a distance map) give the voxels the
// signed Maurer distance map gives (<= -depth, <= reach) voxel for voxel, on a mask of random
// overlapping balls clear of the grid's edge (concave and convex boundaries, thin bridges), on an
// isotropic and an anisotropic grid, at radii on and between voxel distances.
#include "BrainShiftTestingSupport.h"
#include "DistanceMaps.h"

#include <itkImageRegionIteratorWithIndex.h>

#include <cmath>
#include <iostream>
#include <random>

namespace {
using namespace brainshift;

MaskImage::Pointer randomBalls(const std::array<double, 3>& spacing, std::uint32_t seed)
{
  auto mask = MaskImage::New();
  MaskImage::SizeType size;
  MaskImage::SpacingType s;
  for (unsigned a = 0; a < 3; ++a) {
    size[a] = itk::SizeValueType(std::lround(60.0 / spacing[a]));
    s[a] = spacing[a];
  }
  mask->SetRegions(MaskImage::RegionType(size));
  mask->SetSpacing(s);
  mask->Allocate();
  mask->FillBuffer(0);
  std::mt19937 random(seed);
  std::uniform_real_distribution<double> centre(20.0, 40.0), radius(2.0, 12.0);
  for (int ball = 0; ball < 12; ++ball) {
    const double c[3] = {centre(random), centre(random), centre(random)}, r = radius(random);
    for (itk::ImageRegionIteratorWithIndex<MaskImage> it(mask, mask->GetLargestPossibleRegion()); !it.IsAtEnd(); ++it) {
      double d2 = 0;
      for (unsigned a = 0; a < 3; ++a) d2 += std::pow(double(it.GetIndex()[a]) * spacing[a] - c[a], 2);
      if (d2 < r * r) it.Set(1);
    }
  }
  return mask;
}

/// Voxels where `found` and the distance map's test disagree; `agreed` counts those both select.
std::size_t disagreements(const MaskImage& found, const ScalarImage& distance, bool deepTest, double radiusMm, std::size_t& agreed)
{
  std::size_t wrong = 0;
  agreed = 0;
  const std::size_t n = found.GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) {
    const float d = distance.GetBufferPointer()[i];
    const bool expected = deepTest ? d <= -radiusMm : d <= radiusMm;
    const bool got = found.GetBufferPointer()[i] != 0;
    wrong += expected != got;
    agreed += expected && got;
  }
  return wrong;
}
} // namespace

int DistanceMapsTest(int, char*[])
{
  return testing::runTest("DistanceMapsTest", [] {
    for (const std::array<double, 3> spacing : {std::array<double, 3>{1.0, 1.0, 1.0}, std::array<double, 3>{0.9375, 0.9375, 2.5}}) {
      const MaskImage::Pointer mask = randomBalls(spacing, 2000);
      const ScalarImage::Pointer distance = signedDistanceMm(mask);
      std::size_t maskVoxels = 0;
      for (std::size_t i = 0; i < mask->GetLargestPossibleRegion().GetNumberOfPixels(); ++i) maskVoxels += mask->GetBufferPointer()[i];
      for (double radiusMm : {1.0, 2.0, 2.5, 4.0, 6.0}) {
        std::size_t deep = 0, near = 0;
        const std::size_t wrongDeep = disagreements(*voxelsAtLeastDeep(mask, radiusMm), *distance, true, radiusMm, deep);
        const std::size_t wrongNear = disagreements(*voxelsWithin(mask, radiusMm), *distance, false, radiusMm, near);
        std::cout << "spacing " << spacing[0] << "x" << spacing[1] << "x" << spacing[2] << ", " << radiusMm << " mm: " << deep
                  << " deep (" << wrongDeep << " wrong), " << near << " within (" << wrongNear << " wrong) of " << maskVoxels << '\n';
        BS_CHECK_MSG(wrongDeep == 0, wrongDeep << " voxels at least " << radiusMm << " mm deep by one test and not the other");
        BS_CHECK_MSG(wrongNear == 0, wrongNear << " voxels within " << radiusMm << " mm by one test and not the other");
        BS_CHECK_MSG(deep > 50 && deep < maskVoxels, "the depth test selects " << deep << " of " << maskVoxels << " voxels: nothing tested");
        BS_CHECK_MSG(near > maskVoxels, "nothing beyond the mask is within " << radiusMm << " mm");
      }
    }
  });
}
