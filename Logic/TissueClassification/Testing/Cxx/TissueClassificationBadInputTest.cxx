// Bad input names the class or the point: labels without parenchyma, prototypes outside the
// image or of an unknown tissue, too few prototypes for a class, k above a class's count, and
// prototype files that cannot be read.
#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "MarkupsIO.h"
#include "TissueClassificationTestSupport.h"

#include <atomic>

int TissueClassificationBadInputTest(int, char*[])
{
  return brainshift::testing::runTest("TissueClassificationBadInputTest", [] {
    using namespace brainshift;
    const testing::ClassifiedCase c = testing::registeredSmallCase();
    const ScalarImage& intraop = *c.simulated.intraopImage;
    const TissueClassificationParameters parameters;
    const TissueClassificationResult automatic =
      classifyTissues(intraop, *c.simulated.preopLabels, *c.rigid, std::nullopt, parameters);

    // Labels without parenchyma.
    auto copy = LabelImage::New();
    copy->CopyInformation(c.simulated.preopLabels);
    copy->SetRegions(c.simulated.preopLabels->GetLargestPossibleRegion());
    copy->Allocate();
    for (std::size_t i = 0; i < c.simulated.preopLabels->GetLargestPossibleRegion().GetNumberOfPixels(); ++i) {
      const LabelPixel l = c.simulated.preopLabels->GetBufferPointer()[i];
      copy->GetBufferPointer()[i] = l == 2 ? 1 : l;
    }
    BS_CHECK_THROWS(classifyTissues(intraop, *copy, *c.rigid, std::nullopt, parameters), InputError, "no parenchyma");

    // Cancelled (the host's Cancel): CancelledError, no labels.
    std::atomic<bool> cancel{true};
    TissueClassificationParameters cancelled = parameters;
    cancelled.cancel = &cancel;
    BS_CHECK_THROWS(classifyTissues(intraop, *c.simulated.preopLabels, *c.rigid, std::nullopt, cancelled), CancelledError,
                    "tissue classification cancelled");

    // A prototype outside the image names itself.
    std::vector<TissuePrototype> prototypes = automatic.prototypes;
    prototypes[3].name = "stray-point";
    prototypes[3].position[0] += 1000.0;
    BS_CHECK_THROWS(classifyTissues(intraop, *c.simulated.preopLabels, *c.rigid, prototypes, parameters), InputError,
                    "'stray-point'");
    // A tissue the labels do not have.
    prototypes = automatic.prototypes;
    prototypes[0].label = 9;
    prototypes[0].name = "odd";
    BS_CHECK_THROWS(classifyTissues(intraop, *c.simulated.preopLabels, *c.rigid, prototypes, parameters), InputError, "'odd'");
    // Too few prototypes of the ventricles for k = 7: the class is named.
    prototypes.clear();
    unsigned ventricles = 0;
    for (const TissuePrototype& p : automatic.prototypes) {
      if (p.label == 3 && ++ventricles > 5) continue;
      prototypes.push_back(p);
    }
    BS_CHECK_THROWS(classifyTissues(intraop, *c.simulated.preopLabels, *c.rigid, prototypes, parameters), InputError,
                    "5 prototypes of ventricles");
    // k larger than the prototypes of a class.
    TissueClassificationParameters bigK = parameters;
    bigK.k = 151;
    bigK.prototypesPerClass = 151;
    BS_CHECK_THROWS(classifyTissues(intraop, *c.simulated.preopLabels, *c.rigid, automatic.prototypes, bigK), InputError,
                    "k = 151");
    TissueClassificationParameters fewer = parameters;
    fewer.prototypesPerClass = 3;
    BS_CHECK_THROWS(classifyTissues(intraop, *c.simulated.preopLabels, *c.rigid, std::nullopt, fewer), InputError,
                    "fewer than k");

    // Prototype files.
    const auto folder = testing::temporaryFolder("TissueClassificationBadInputTest");
    writeMarkupsJson({{"parenchyma-1", c.simulated.landmarks[0].intraop}, {"ventricles", c.simulated.landmarks[1].intraop},
                      {"3-x", c.simulated.landmarks[2].intraop}},
                     folder / "picked.mrk.json");
    const std::vector<TissuePrototype> picked = readPrototypes(folder / "picked.mrk.json");
    BS_CHECK(picked.size() == 3 && picked[0].label == 2 && picked[1].label == 3 && picked[2].label == 3);
    writeMarkupsJson({{"grey-1", c.simulated.landmarks[0].intraop}}, folder / "unnamed.mrk.json");
    BS_CHECK_THROWS(readPrototypes(folder / "unnamed.mrk.json"), InputError, "'grey-1'");
    writeTextFileAtomically(folder / "broken.json", "{\"frame\": \"preop\"}");
    BS_CHECK_THROWS(readPrototypes(folder / "broken.json"), InputError, "broken.json");
  });
}
