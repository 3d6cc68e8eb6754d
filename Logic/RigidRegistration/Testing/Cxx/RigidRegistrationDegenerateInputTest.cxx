// Images too small or featureless to register are refused, not registered (issue 18): a 4x4x4
// intraoperative image once gave a "trustworthy" 62 degree rotation, a one-voxel foreground an
// internal ITK error ("A spacing of 0 is not allowed").
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "RigidRegistrationTestSupport.h"

#include <itkImageRegionIteratorWithIndex.h>
#include <itkRegionOfInterestImageFilter.h>

#include <cmath>

#include <iostream>

namespace {
using namespace brainshift;

/// A copy of `image` restricted to `size` voxels about its centre (the same physical place).
ScalarImage::Pointer centralBlock(const ScalarImage& image, unsigned size)
{
  ScalarImage::RegionType region;
  for (unsigned d = 0; d < 3; ++d) {
    region.SetIndex(d, long(image.GetLargestPossibleRegion().GetSize()[d] / 2) - long(size / 2));
    region.SetSize(d, size);
  }
  auto crop = itk::RegionOfInterestImageFilter<ScalarImage, ScalarImage>::New();
  crop->SetInput(&image);
  crop->SetRegionOfInterest(region);
  crop->Update();
  return crop->GetOutput();
}

ScalarImage::Pointer filledLike(const ScalarImage& image, float value)
{
  auto out = ScalarImage::New();
  out->CopyInformation(&image);
  out->SetRegions(image.GetLargestPossibleRegion());
  out->Allocate();
  out->FillBuffer(value);
  return out;
}
} // namespace

int RigidRegistrationDegenerateInputTest(int, char*[])
{
  return brainshift::testing::runTest("RigidRegistrationDegenerateInputTest", [] {
    const SimulatedCase c = testing::smallCaseWithMotion({4.0, -3.0, 6.0}, {6.0, -8.0, 5.0});
    const auto spacing = c.intraopImage->GetSpacing();
    std::cout << "intraoperative spacing " << spacing[0] << " x " << spacing[1] << " x " << spacing[2] << " mm\n";

    // A 4x4x4 block of the intraoperative image: too small for the pyramid, bad input.
    const ScalarImage::Pointer tiny = centralBlock(*c.intraopImage, 4);
    BS_CHECK_THROWS(registerRigidly(*tiny, *c.preopImage, c.preopLabels, {}), InputError, "too small to register");
    BS_CHECK_THROWS(registerRigidly(*c.intraopImage, *tiny, nullptr, {}), InputError, "preoperative image is too small");

    // One bright voxel in a dark image of full size: a foreground of one coarse voxel.
    const ScalarImage::Pointer speck = filledLike(*c.intraopImage, 0.0f);
    ScalarImage::IndexType centre;
    for (unsigned d = 0; d < 3; ++d) centre[d] = long(speck->GetLargestPossibleRegion().GetSize()[d] / 2);
    speck->SetPixel(centre, 500.0f);
    BS_CHECK_THROWS(registerRigidly(*speck, *c.preopImage, c.preopLabels, {}), InputError,
                    "intraoperative image's foreground is too small to register: it spans 1 x 1 x 1");

    // A uniform block (60 voxels a side) in a dark image: a foreground without any feature.
    const ScalarImage::Pointer block = filledLike(*c.intraopImage, 0.0f);
    itk::ImageRegionIteratorWithIndex<ScalarImage> voxel(block, block->GetLargestPossibleRegion());
    for (; !voxel.IsAtEnd(); ++voxel) {
      bool inside = true;
      for (unsigned d = 0; d < 3; ++d) inside = inside && std::abs(voxel.GetIndex()[d] - centre[d]) < 30;
      if (inside) voxel.Set(300.0f);
    }
    BS_CHECK_THROWS(registerRigidly(*block, *c.preopImage, c.preopLabels, {}), InputError,
                    "intraoperative image's foreground is uniform");

    // A constant image: no feature at all, on either side.
    const ScalarImage::Pointer constant = filledLike(*c.intraopImage, 120.0f);
    BS_CHECK_THROWS(registerRigidly(*constant, *c.preopImage, c.preopLabels, {}), InputError,
                    "intraoperative image is constant (every voxel 120)");
    BS_CHECK_THROWS(prepareRigidMoving(*filledLike(*c.preopImage, 7.0f), nullptr, {}), InputError,
                    "preoperative image is constant");

    // Too few valid samples for mutual information: the result is flagged, with the reason.
    RigidRegistrationParameters demanding;
    demanding.minimumValidSamples = 1000000;
    const RigidRegistrationResult flagged = registerRigidly(*c.intraopImage, *c.preopImage, c.preopLabels, demanding);
    BS_CHECK_MSG(!flagged.trustworthy && flagged.failureReason.find("samples of the intraoperative foreground") != std::string::npos,
                 flagged.failureReason);
    BS_CHECK_MSG(flagged.validSamples > 10000 && flagged.validSamples <= demanding.samplesPerLevel.back(), flagged.validSamples);

    // The checks leave a normal case alone.
    const RigidRegistrationResult normal = registerRigidly(*c.intraopImage, *c.preopImage, c.preopLabels, {});
    BS_CHECK_MSG(normal.trustworthy, normal.failureReason);
    BS_CHECK_MSG(normal.validSamples >= 500, normal.validSamples);
  });
}
