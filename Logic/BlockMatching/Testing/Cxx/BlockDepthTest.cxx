// The block centres' depth test (depthTestOffsets: every offset brain) is the signed Maurer
// distance map's test (distance <= -depth) voxel for voxel, on a mask of random overlapping balls
// (concave and convex boundaries, thin bridges; clear of the grid's edge, where ITK sees no
// boundary and the block matching's test says "not deep"), on an isotropic and an anisotropic
// grid and at depths on and between voxel distances. A neighbourhood of the 6 face neighbours instead of 26
// disagrees on this mask (checked), so the comparison can fail.
#include "BlockMatching.h"
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
  return brainshift::testing::makeRandomBallsMask(spacing, 60.0, 9, {18.0, 42.0}, {4.0, 14.0}, seed);
}

/// Voxels where the two tests disagree; `deep` counts those both call deep enough.
std::size_t disagreements(const MaskImage& mask, const std::array<double, 3>& spacing, double depthMm, std::size_t& deep)
{
  const ScalarImage::Pointer distance = signedDistanceMm(&mask);
  const std::vector<std::array<int, 3>> offsets = depthTestOffsets(spacing, depthMm);
  const auto size = mask.GetLargestPossibleRegion().GetSize();
  auto at = [&](long i, long j, long k) { return std::size_t(i) + size[0] * (std::size_t(j) + size[1] * std::size_t(k)); };
  std::size_t wrong = 0;
  deep = 0;
  for (long k = 0; k < long(size[2]); ++k)
    for (long j = 0; j < long(size[1]); ++j)
      for (long i = 0; i < long(size[0]); ++i) {
        if (!mask.GetBufferPointer()[at(i, j, k)]) continue;
        bool byOffsets = true;
        for (const auto& o : offsets) {
          const long x = i + o[0], y = j + o[1], z = k + o[2];
          const bool inside = x >= 0 && y >= 0 && z >= 0 && x < long(size[0]) && y < long(size[1]) && z < long(size[2]);
          byOffsets = byOffsets && inside && mask.GetBufferPointer()[at(x, y, z)];
        }
        const bool byDistance = -distance->GetBufferPointer()[at(i, j, k)] >= depthMm;
        wrong += byOffsets != byDistance;
        deep += byOffsets && byDistance;
      }
  return wrong;
}
} // namespace

int BlockDepthTest(int, char*[])
{
  return testing::runTest("BlockDepthTest", [] {
  for (const std::array<double, 3> spacing : {std::array<double, 3>{1.0, 1.0, 1.0}, std::array<double, 3>{0.9, 1.1, 2.5}}) {
    const MaskImage::Pointer mask = randomBalls(spacing, 2000);
    for (double depthMm : {1.0, 2.5, 4.0, 6.0}) {
      std::size_t deep = 0;
      const std::size_t wrong = disagreements(*mask, spacing, depthMm, deep);
      std::cout << "spacing " << spacing[0] << "x" << spacing[1] << "x" << spacing[2] << ", depth " << depthMm << " mm: " << deep
                << " voxels deep enough, " << wrong << " disagreements\n";
      BS_CHECK_MSG(wrong == 0, wrong << " voxels where the offsets and the distance map disagree");
      BS_CHECK_MSG(deep > 100, "the mask leaves too few deep voxels to test anything: " << deep);
    }
  }
  });
}
