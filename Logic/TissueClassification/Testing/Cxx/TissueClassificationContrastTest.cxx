// The classification's intensity rules hold in any contrast: they are stated through what the
// prototypes learned of this scan (ScanContrast: the medians of air, fluid and parenchyma), not
// through a T1 order. Synthetic medians first (a T1 order and an inverted, T2-like one), then the
// small built-in case seen by a T2-weighted scanner (fluid bright, white matter dark, air dark),
// the tumour resected and in place: the fluid rule once took T2's dark white matter for fluid
// (brain Dice 0.89 at this size) and the air in the cavity for tumour (the resection missed).
#include "BrainShiftTestingSupport.h"
#include "TissueClassificationTestSupport.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <vector>

namespace {
using namespace brainshift;

testing::ClassifiedCase t2Case(bool resection)
{
  CaseParameters parameters = caseScenario("rf10-t2").parameters; // fluid under air, 10 mm, T2
  parameters.size = CaseSize::Small;
  parameters.resection = resection;
  testing::ClassifiedCase c{simulateCase(parameters), nullptr};
  c.rigid = registerRigidly(*c.simulated.intraopImage, *c.simulated.preopImage, c.simulated.preopLabels, {}).intraopToPreop;
  return c;
}
} // namespace

int TissueClassificationContrastTest(int, char*[])
{
  return brainshift::testing::runTest("TissueClassificationContrastTest", [] {
    using namespace brainshift;
    // T1 order: air 1 < fluid 15 < parenchyma 60. Fluid or air below halfway from fluid to parenchyma.
    std::map<LabelPixel, std::vector<float>> t1Prototypes{{0, {0.f, 1.f, 2.f}}, {2, {58.f, 60.f, 62.f}}, {3, {14.f, 15.f, 16.f}}};
    const ScanContrast t1 = scanContrastOf(t1Prototypes);
    BS_CHECK(t1.air == 1.0 && t1.fluid == 15.0 && t1.parenchyma == 60.0);
    BS_CHECK(!t1.fluidBrighterThanParenchyma());
    BS_CHECK(t1.looksLikeFluidOrAir(0.0) && t1.looksLikeFluidOrAir(15.0) && t1.looksLikeFluidOrAir(37.0));
    BS_CHECK(!t1.looksLikeFluidOrAir(38.0) && !t1.looksLikeFluidOrAir(60.0) && !t1.looksLikeFluidOrAir(90.0));
    // Inverted (T2-like): air 1 < parenchyma 40 < fluid 60. The bright fluid and the dark air are
    // both not tissue; the white matter, darker than the parenchyma's median, is tissue.
    std::map<LabelPixel, std::vector<float>> t2Prototypes{{0, {1.f}}, {2, {40.f}}, {3, {60.f}}};
    const ScanContrast t2 = scanContrastOf(t2Prototypes);
    BS_CHECK(t2.fluidBrighterThanParenchyma());
    BS_CHECK(t2.looksLikeFluidOrAir(75.0) && t2.looksLikeFluidOrAir(55.0) && t2.looksLikeFluidOrAir(5.0) && t2.looksLikeFluidOrAir(15.0));
    BS_CHECK(!t2.looksLikeFluidOrAir(45.0) && !t2.looksLikeFluidOrAir(32.0) && !t2.looksLikeFluidOrAir(25.0));
    // Without ventricles (fluid unknown) only air is told from the parenchyma.
    std::map<LabelPixel, std::vector<float>> noFluid{{0, {1.f}}, {2, {40.f}}};
    const ScanContrast dry = scanContrastOf(noFluid);
    BS_CHECK(std::isnan(dry.fluid) && dry.looksLikeFluidOrAir(10.0) && !dry.looksLikeFluidOrAir(60.0));

    // The small case, T2: the brain found, the tumour's fate decided right both ways.
    for (bool resection : {true, false}) {
      const testing::ClassifiedCase c = t2Case(resection);
      TissueClassificationParameters parameters;
      takePreoperativeImage(parameters, *c.simulated.preopImage, *c.simulated.preopLabels, *c.rigid);
      const TissueClassificationResult result =
        classifyTissues(*c.simulated.intraopImage, *c.simulated.preopLabels, *c.rigid, std::nullopt, parameters);
      const ScanContrast& learned = result.contrast;
      const TumourResectionEvidence& e = result.tumourEvidence;
      std::cout << (resection ? "resected" : "in place") << ": air " << learned.air << ", fluid " << learned.fluid
                << ", parenchyma " << learned.parenchyma << "; fluid-like " << e.fluidLikeShare << " (air " << e.airLikeShare << "), tumour-like "
                << e.tumourLikeShare << "\n";
      BS_CHECK(learned.fluidBrighterThanParenchyma());
      BS_CHECK(learned.air < learned.parenchyma);
      BS_CHECK_MSG(result.tumourResected == resection, "decided " << result.tumourResected);
      const testing::Scores s = testing::scoresOf(*result.labels, c.simulated, resection ? "T2, resected" : "T2, in place");
      BS_CHECK_MSG(s.brain > 0.93, s.brain);
      BS_CHECK_MSG(s.surfaceMm < 2.0, s.surfaceMm);
      // The fluid under the craniotomy looks like the cortex in this contrast: said once.
      const auto fluidLike = std::count_if(result.warnings.begin(), result.warnings.end(), [](const std::string& w) {
        return w.find("fluid is brighter than its parenchyma") != std::string::npos;
      });
      BS_CHECK_MSG(fluidLike == 1, fluidLike << " warnings of fluid like the cortex");
    }
  });
}
