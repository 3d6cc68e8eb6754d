// The hard scenarios of the built-in case do what their names say, on the small case: fluid under
// air in the gap (the air above the level that gravity sets), the cavity's bright rim, another
// scanner's contrast (T2: fluid brighter than white matter; FLAIR: fluid dark; low-field: grey and
// white closer), the tumour's looks, tumour-margin landmarks for a tumour left in place, and the
// catalogue: at least 12 variants, every site and shift from 5 to 20 mm, named uniquely.
#include "BrainShiftTestingSupport.h"
#include "CaseSimulationTestSupport.h"
#include "DistanceMaps.h"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <set>

namespace {
using namespace brainshift;

/// Median intraoperative intensity over the voxels whose true label is `label` (and, for label 0,
/// inside the preoperative brain as the truth moved it: the gap and the cavity).
struct TissueMedians {
  double fluid = 0, parenchyma = 0, ventricles = 0;
};

double median(std::vector<float> v)
{
  if (v.empty()) return std::nan("");
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
  return v[v.size() / 2];
}

TissueMedians mediansOf(const SimulatedCase& c)
{
  std::vector<float> parenchyma, ventricles;
  const float* image = c.intraopImage->GetBufferPointer();
  const LabelPixel* truth = c.intraopLabels->GetBufferPointer();
  for (std::size_t i = 0, n = c.intraopLabels->GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) {
    if (truth[i] == 2) parenchyma.push_back(image[i]);
    if (truth[i] == 3) ventricles.push_back(image[i]);
  }
  return {0, median(parenchyma), median(ventricles)};
}

CaseParameters smallScenario(const std::string& name)
{
  CaseParameters p = caseScenario(name).parameters;
  p.size = CaseSize::Small;
  return p;
}
} // namespace

int CaseSimulationScenarioTest(int, char*[])
{
  return brainshift::testing::runTest("CaseSimulationScenarioTest", [] {
    using namespace brainshift;
    // The catalogue.
    const auto& scenarios = caseScenarios();
    BS_CHECK_MSG(scenarios.size() >= 13, scenarios.size());
    BS_CHECK(scenarios.front().name == "default");
    std::set<std::string> names;
    std::set<CraniotomySite> sites;
    std::set<double> shifts;
    std::size_t intact = 0, lowField = 0;
    for (const CaseScenario& s : scenarios) {
      names.insert(s.name);
      sites.insert(s.parameters.craniotomy);
      shifts.insert(s.parameters.shiftMillimetres);
      intact += !s.parameters.resection;
      lowField += s.parameters.contrast == IntraopContrast::LowFieldT1;
      s.parameters.validate();
    }
    BS_CHECK(names.size() == scenarios.size());
    BS_CHECK(sites.size() >= 4);
    BS_CHECK(shifts.count(5.0) && shifts.count(10.0) && shifts.count(15.0) && shifts.count(20.0));
    BS_CHECK(intact >= 4 && lowField >= 4);
    BS_CHECK_THROWS(caseScenario("no-such-scenario"), InputError, "default");
    BS_CHECK_THROWS(intraopContrastFromString("pd"), InputError, "low-field-t1");

    // Fluid under air in the gap and the cavity, the level set by gravity.
    {
      const SimulatedCase c = simulateCase(smallScenario("rf15-cavityrim"));
      const CaseFigures& f = c.figures;
      std::cout << "gap " << f.gapVolumeMl << " ml (air " << f.gapAirMl << "), cavity " << f.cavityVolumeMl << " ml (air "
                << f.cavityAirMl << ")\n";
      BS_CHECK(f.gapVolumeMl > 5.0);
      BS_CHECK(f.gapAirMl > 0.1 * f.gapVolumeMl && f.gapAirMl < 0.7 * f.gapVolumeMl); // 40 % air by volume
      BS_CHECK(f.cavityAirMl > 0.0 && f.cavityAirMl < 0.5 * f.cavityVolumeMl);
      BS_CHECK(f.minJacobianDeterminant > 0);
    }
    // Contrast: T2 turns the order of fluid and tissue over, FLAIR keeps fluid dark, low field
    // brings grey and white closer.
    {
      CaseParameters p = smallScenario("default");
      p.contrast = IntraopContrast::T2;
      const TissueMedians t2 = mediansOf(simulateCase(p));
      p.contrast = IntraopContrast::Flair;
      const TissueMedians flair = mediansOf(simulateCase(p));
      p.contrast = IntraopContrast::T1;
      const TissueMedians t1 = mediansOf(simulateCase(p));
      std::cout << "ventricles / parenchyma: T1 " << t1.ventricles / t1.parenchyma << ", T2 " << t2.ventricles / t2.parenchyma
                << ", FLAIR " << flair.ventricles / flair.parenchyma << "\n";
      BS_CHECK(t1.ventricles < 0.7 * t1.parenchyma);
      BS_CHECK(t2.ventricles > 1.3 * t2.parenchyma);
      BS_CHECK(flair.ventricles < 0.6 * flair.parenchyma);
    }
    // T1 post-contrast: the T1 map, and the tissue lining the cavity and the dura around the
    // craniotomy enhance (1.6 of the white matter before the map). The same seed draws the same
    // noise and bias, so voxel by voxel the post-contrast scan is the T1 one or brighter.
    {
      CaseParameters p = smallScenario("default");
      const SimulatedCase plain = simulateCase(p);
      p.contrast = IntraopContrast::T1PostContrast;
      const SimulatedCase post = simulateCase(p);
      std::size_t brighter[5] = {0, 0, 0, 0, 0}, darker = 0;
      const float* a = plain.intraopImage->GetBufferPointer();
      const float* b = post.intraopImage->GetBufferPointer();
      const LabelPixel* truth = post.intraopLabels->GetBufferPointer();
      for (std::size_t i = 0, n = post.intraopLabels->GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) {
        if (b[i] > 1.15f * a[i] + 30.f) brighter[std::min<LabelPixel>(truth[i], 4)] += 1;
        if (b[i] < 0.95f * a[i] - 30.f) ++darker;
      }
      std::cout << "enhanced voxels: background " << brighter[0] << ", head (dura) " << brighter[1] << ", parenchyma (cavity lining) "
                << brighter[2] << "; darker " << darker << "\n";
      BS_CHECK_MSG(brighter[1] > 100 && brighter[2] > 30, brighter[1] << ", " << brighter[2]);
      BS_CHECK_MSG(darker == 0, darker);
      BS_CHECK(toString(IntraopContrast::T1PostContrast) == "t1-post-contrast");
      BS_CHECK(intraopContrastFromString("t1-post-contrast") == IntraopContrast::T1PostContrast);
      BS_CHECK(caseScenario("rf10-t1post-intact").parameters.contrast == IntraopContrast::T1PostContrast);
      BS_CHECK(caseScenario("rf10-t2").parameters.seed == 2114); // the catalogue's seeds are kept
    }
    // A tumour left in place: landmarks on its margin, none near a cavity; its look preoperatively.
    {
      const SimulatedCase c = simulateCase(smallScenario("lf10-intact-isointense"));
      std::size_t margin = 0, cavity = 0;
      for (const LandmarkPair& l : c.landmarks) {
        margin += l.name.rfind("tumour-margin-", 0) == 0;
        cavity += l.name.rfind("near-cavity-", 0) == 0;
      }
      BS_CHECK_MSG(margin >= 3 && cavity == 0, margin << " margin, " << cavity << " near a cavity");
      BS_CHECK(c.figures.cavityVolumeMl == 0.0);
    }
    // The tumour's depth: its centre 22 mm below the cortex by default (along the craniotomy's
    // axis its top 12 mm deep), 13 mm in the superficial scenarios, where it reaches the cortex (the
    // outer 3 mm kept).
    {
      auto shallowestTumourMm = [](const CaseParameters& p) {
        const SimulatedCase c = simulateCase(p);
        auto brain = MaskImage::New();
        brain->CopyInformation(c.preopLabels);
        brain->SetRegions(c.preopLabels->GetLargestPossibleRegion());
        brain->Allocate();
        const LabelPixel* l = c.preopLabels->GetBufferPointer();
        unsigned char* m = brain->GetBufferPointer();
        const std::size_t n = c.preopLabels->GetLargestPossibleRegion().GetNumberOfPixels();
        for (std::size_t i = 0; i < n; ++i) m[i] = l[i] >= 2;
        const ScalarImage::Pointer toSurface = signedDistanceMm(brain); // negative inside
        const float* d = toSurface->GetBufferPointer();
        float shallowest = 1e9f;
        for (std::size_t i = 0; i < n; ++i) {
          if (l[i] == 4) shallowest = std::min(shallowest, -d[i]);
        }
        return shallowest;
      };
      const CaseParameters superficial = smallScenario("rf20-superficial-intact");
      BS_CHECK(superficial.tumourDepthMm == 13.0 && !superficial.resection);
      BS_CHECK(caseScenario("lp15-fe-superficial-intact").parameters.truth == TruthModel::FiniteElementSliding);
      const float deep = shallowestTumourMm(smallScenario("default")), near = shallowestTumourMm(superficial);
      std::cout << "the tumour's shallowest voxel below the cortex: default " << deep << " mm, superficial " << near << " mm\n";
      // Measured on the small case (2 mm grid; the nearest surface may be a sulcus beside the
      // craniotomy): 5.7 and 3.5 mm.
      BS_CHECK_MSG(near < 4.0f, near);
      BS_CHECK_MSG(deep > near + 2.0f, deep << " against " << near);
      CaseParameters tooShallow = superficial;
      tooShallow.tumourDepthMm = 5.0;
      BS_CHECK_THROWS(tooShallow.validate(), InputError, "--tumour-depth");
      tooShallow.tumourDepthMm = std::nan("");
      BS_CHECK_THROWS(tooShallow.validate(), InputError, "--tumour-depth");
    }
  });
}
