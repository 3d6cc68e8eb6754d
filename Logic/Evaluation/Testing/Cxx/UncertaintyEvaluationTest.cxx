// The confidence map's validation against a known truth: an update whose error grows along x
// (|error| = 0.1 mm per voxel), scored against estimates that rank it right, backwards, or not at all.
#include "BrainShiftTestingSupport.h"
#include "SyntheticData.h"
#include "UncertaintyEvaluation.h"

#include <itkIdentityTransform.h>

#include <cmath>
#include <iostream>

int UncertaintyEvaluationTest(int, char*[])
{
  return brainshift::testing::runTest("UncertaintyEvaluationTest", [] {
    using namespace brainshift;
    const ImageGeometry grid = testing::grid({{20, 16, 12}}, {2.0, 2.0, 2.0}, testing::point(-20, -16, -12));
    // The update maps y to y + d(y); the truth is the identity, so the true error is |d| = 0.1 (x + 20) / 2 mm.
    auto errorAt = [](const PhysicalPoint& p) { return 0.05 * (p[0] + 20.0); };
    const auto update = testing::imageOn<DisplacementFieldImage>(grid, [&](const PhysicalPoint& p) {
      DisplacementVector d;
      d[0] = 0.6 * errorAt(p);
      d[1] = -0.8 * errorAt(p);
      d[2] = 0.0;
      return d;
    });
    const auto brain = testing::imageOn<LabelImage>(grid, [](const PhysicalPoint& p) { return LabelPixel(p[2] < 8 ? 2 : 0); });
    const auto truth = itk::IdentityTransform<double, 3>::New();
    const auto right = testing::imageOn<ScalarImage>(grid, [&](const PhysicalPoint& p) { return float(errorAt(p)); });
    const auto backwards = testing::imageOn<ScalarImage>(grid, [&](const PhysicalPoint& p) { return float(2.0 - errorAt(p)); });
    const auto flat = testing::imageOn<ScalarImage>(grid, [](const PhysicalPoint&) { return 0.5f; });

    const UncertaintyValidation r = validateUncertainty(*update, *truth, *right, *brain, {2}, 1);
    std::cout << r.voxels << " voxels; rank correlation right " << r.rankCorrelation << ", mean true error " << r.meanTrueErrorMm
              << " mm, called below 1 mm " << r.shareCalledBelow1Mm << ", of them truly below 1.5 mm " << r.calledBelow1MmTrulyBelow1_5Mm
              << '\n';
    BS_CHECK(r.voxels == 20 * 16 * 10);
    BS_CHECK_NEAR(r.rankCorrelation, 1.0, 1e-9);
    BS_CHECK_NEAR(r.meanTrueErrorMm, 0.05 * 19.0, 1e-6); // x + 20 runs over 0, 2, ..., 38
    BS_CHECK_NEAR(r.shareCalledBelow1Mm, 10.0 / 20.0, 1e-9); // x + 20 < 20: ten of the twenty columns
    BS_CHECK_NEAR(r.calledBelow1MmTrulyBelow1_5Mm, 1.0, 1e-9);
    BS_CHECK_NEAR(r.trueErrorWhereCalledAbove2MmMm, 0.0, 1e-9); // it never says 2 mm
    BS_CHECK_NEAR(double(r.trueError->GetPixel({{19, 0, 0}})), 0.05 * 38.0, 1e-5);

    const UncertaintyValidation b = validateUncertainty(*update, *truth, *backwards, *brain, {2}, 1);
    BS_CHECK_NEAR(b.rankCorrelation, -1.0, 1e-9);
    // Called below 1 mm where the truth is 1.1 to 1.9 mm (nine columns): four of them below 1.5 mm.
    BS_CHECK_NEAR(b.calledBelow1MmTrulyBelow1_5Mm, 4.0 / 9.0, 1e-9);
    const UncertaintyValidation f = validateUncertainty(*update, *truth, *flat, *brain, {2}, 1);
    BS_CHECK_NEAR(f.rankCorrelation, 0.0, 1e-9);

    const ImageGeometry other = testing::grid({{10, 16, 12}}, {2.0, 2.0, 2.0}, testing::point(-20, -16, -12));
    const auto elsewhere = testing::imageOn<ScalarImage>(other, [](const PhysicalPoint&) { return 0.5f; });
    BS_CHECK_THROWS(validateUncertainty(*update, *truth, *elsewhere, *brain), std::invalid_argument, "not on the update's grid");
  });
}
