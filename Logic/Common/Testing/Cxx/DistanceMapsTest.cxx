// voxelsAtLeastDeep and voxelsWithin (the morphology without a distance map) give the voxels the
// signed Maurer distance map gives (<= -depth, <= reach) voxel for voxel, on a mask of random
// overlapping balls clear of the grid's edge (concave and convex boundaries, thin bridges), and
// voxelsWithin also on balls cut by the grid's edges, on an
// isotropic and two anisotropic grids, at radii on and between voxel distances. Block matching
// tests its centres with the same offsets (depthTestOffsets).
#include "BrainShiftTestingSupport.h"
#include "DistanceMaps.h"
#include "SyntheticData.h"

#include <itkImageRegionIteratorWithIndex.h>

#include <cmath>
#include <iostream>

namespace {
using namespace brainshift;

MaskImage::Pointer randomBalls(const std::array<double, 3>& spacing, std::uint32_t seed)
{
  return brainshift::testing::makeRandomBallsMask(spacing, 60.0, 12, {20.0, 40.0}, {2.0, 12.0}, seed);
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
    for (const std::array<double, 3> spacing : {std::array<double, 3>{1.0, 1.0, 1.0}, std::array<double, 3>{0.9375, 0.9375, 2.5},
                                                 std::array<double, 3>{0.9, 1.1, 2.5}}) {
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
      // Balls cut by the grid's edges (the trust's box may end at the scan's edge): voxelsWithin
      // still gives what the distance map gives.
      const MaskImage::Pointer cut = brainshift::testing::makeRandomBallsMask(spacing, 60.0, 12, {0.0, 20.0}, {2.0, 12.0}, 2001);
      const ScalarImage::Pointer cutDistance = signedDistanceMm(cut);
      std::size_t onEdge = 0; // mask voxels on the grid's first x face: the balls are cut there
      const auto cutSize = cut->GetLargestPossibleRegion().GetSize();
      for (std::size_t row = 0; row < cutSize[1] * cutSize[2]; ++row) onEdge += cut->GetBufferPointer()[row * cutSize[0]] != 0;
      BS_CHECK_MSG(onEdge > 10, onEdge << " mask voxels on the grid's edge: the balls are not cut");
      for (double radiusMm : {2.5, 5.0}) {
        std::size_t near = 0;
        const std::size_t wrongNear = disagreements(*voxelsWithin(cut, radiusMm), *cutDistance, false, radiusMm, near);
        std::cout << "  cut by the edges, " << radiusMm << " mm: " << near << " within (" << wrongNear << " wrong)\n";
        BS_CHECK_MSG(wrongNear == 0, wrongNear << " voxels within " << radiusMm << " mm of balls cut by the edges by one test and not the other");
        BS_CHECK_MSG(near > 100, "nothing within " << radiusMm << " mm of the cut balls");
      }
    }
  });
}
