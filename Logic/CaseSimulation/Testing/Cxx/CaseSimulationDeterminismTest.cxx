// The same parameters give the same case, bit for bit; another seed another noise; bad
// parameters and a missing template are refused with a clear error.
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "CaseSimulationTestSupport.h"

#include <cstring>

int CaseSimulationDeterminismTest(int, char*[])
{
  return brainshift::testing::runTest("CaseSimulationDeterminismTest", [] {
    using namespace brainshift;
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    const SimulatedCase& first = testing::smallCase();
    const SimulatedCase again = simulateCase(parameters);
    const std::size_t voxels = again.intraopImage->GetLargestPossibleRegion().GetNumberOfPixels();
    BS_CHECK(std::memcmp(first.intraopImage->GetBufferPointer(), again.intraopImage->GetBufferPointer(),
                         voxels * sizeof(float)) == 0);
    BS_CHECK(first.landmarks.size() == again.landmarks.size());
    for (std::size_t i = 0; i < first.landmarks.size(); ++i) {
      BS_CHECK(first.landmarks[i].name == again.landmarks[i].name);
      BS_CHECK(first.landmarks[i].preop == again.landmarks[i].preop);
    }

    parameters.seed += 1;
    const SimulatedCase other = simulateCase(parameters);
    BS_CHECK(std::memcmp(first.intraopImage->GetBufferPointer(), other.intraopImage->GetBufferPointer(),
                         voxels * sizeof(float)) != 0);

    CaseParameters bad;
    bad.shiftMillimetres = 40;
    BS_CHECK_THROWS(simulateCase(bad), InputError, "--shift");
    bad = CaseParameters{};
    bad.noiseFraction = std::nan("");
    BS_CHECK_THROWS(simulateCase(bad), InputError, "--noise");
    bad = CaseParameters{};
    bad.templateFolder = "/nonexistent/templates";
    BS_CHECK_THROWS(simulateCase(bad), InputError, "/nonexistent/templates/ch2.nii.gz");
    BS_CHECK_THROWS(craniotomySiteFromString("occipital"), InputError, "right-frontal");
    BS_CHECK(craniotomySiteFromString("left-parietal") == CraniotomySite::LeftParietal);
  });
}
