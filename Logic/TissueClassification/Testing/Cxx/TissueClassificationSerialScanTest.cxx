// Serial use: the prototypes recorded on the first scan, written and read back, classify the
// same scan identically and a later scan (another acquisition of the same case) without any
// interaction.
#include "BrainShiftTestingSupport.h"
#include "TissueClassificationTestSupport.h"

#include <cstring>

int TissueClassificationSerialScanTest(int, char*[])
{
  return brainshift::testing::runTest("TissueClassificationSerialScanTest", [] {
    using namespace brainshift;
    const TissueClassificationParameters parameters;
    const testing::ClassifiedCase first = testing::registeredSmallCase();
    const TissueClassificationResult automatic =
      classifyTissues(*first.simulated.intraopImage, *first.simulated.preopLabels, *first.rigid, std::nullopt, parameters);
    const auto file = testing::temporaryFolder("TissueClassificationSerialScanTest") / "classification_prototypes.json";
    writePrototypes(automatic.prototypes, file);
    const std::vector<TissuePrototype> recorded = readPrototypes(file);
    BS_CHECK(recorded.size() == automatic.prototypes.size());
    BS_CHECK(recorded.front().name == automatic.prototypes.front().name && recorded.front().label == automatic.prototypes.front().label);

    // The same scan with the recorded prototypes (the resected tumour's ones dropped the same way).
    const TissueClassificationResult again =
      classifyTissues(*first.simulated.intraopImage, *first.simulated.preopLabels, *first.rigid, recorded, parameters);
    const std::size_t voxels = automatic.voxels;
    BS_CHECK(std::memcmp(again.labels->GetBufferPointer(), automatic.labels->GetBufferPointer(), voxels * sizeof(LabelPixel)) == 0);

    // A later scan: new noise, the recorded positions re-sampled there.
    const testing::ClassifiedCase later = testing::registeredSmallCase(true, 0.03, 2001);
    const TissueClassificationResult serial =
      classifyTissues(*later.simulated.intraopImage, *later.simulated.preopLabels, *later.rigid, recorded, parameters);
    const testing::Scores s = testing::scoresOf(*serial.labels, later.simulated, "later scan");
    BS_CHECK_MSG(s.brain >= 0.95, s.brain);
    BS_CHECK_MSG(s.surfaceMm <= 1.0, s.surfaceMm);
  });
}
