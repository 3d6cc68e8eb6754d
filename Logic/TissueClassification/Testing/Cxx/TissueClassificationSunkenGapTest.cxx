// The gap under a craniotomy the brain sank 20 mm away from (scenarios rf20-lowfield and
// lp20-cavityrim, small size): the aligned preoperative brain still covers it, so the k-NN gives
// its shallow part to the head and its deep part to the brain (a tumour kept by mistake: to the
// tumour). Thick fluid is measured over what the k-NN or the aligned brain calls brain, so the
// gap's fluid is one thick body and leaves the brain; measured over the k-NN's brain alone, the
// brain-labelled rest of the gap is a sheet too thin to count, and the classification's boundary
// stops millimetres short of the sunken brain (the surface's imposed displacements with it). Given
// the preoperative image, the gap also takes the fluid next to it that was brain before surgery. The
// tumour, decided in place in both (its cavity moved away from the rigid prior), keeps only what
// does not look more like fluid than the tumour did before surgery. In T2 neither applies.
#include "BrainShiftTestingSupport.h"
#include "TissueClassificationTestSupport.h"

#include <itkImageRegionConstIteratorWithIndex.h>

#include <cmath>

namespace {
using namespace brainshift;

/// Voxels classified brain (2, 3, 4) that the truth says are not brain although the rigidly aligned
/// preoperative brain covers them (the gap the brain sank away from, and the cavity), in ml.
double gapTakenForBrainMl(const LabelImage& labels, const SimulatedCase& c)
{
  auto isBrain = [](LabelPixel l) { return l >= 2 && l <= 4; };
  const LabelImage& truth = *c.intraopLabels;
  const LabelImage& preop = *c.preopLabels;
  std::size_t count = 0;
  itk::ImageRegionConstIteratorWithIndex<LabelImage> it(&labels, labels.GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    if (!isBrain(it.Get()) || isBrain(truth.GetPixel(it.GetIndex()))) continue;
    PhysicalPoint x;
    labels.TransformIndexToPhysicalPoint(it.GetIndex(), x);
    itk::Index<3> before;
    if (preop.TransformPhysicalPointToIndex(c.rigidIntraopToPreop->TransformPoint(x), before) && isBrain(preop.GetPixel(before))) ++count;
  }
  const auto s = labels.GetSpacing();
  return double(count) * s[0] * s[1] * s[2] / 1000.0;
}
/// The gap takes the fluid within its reach of path (6 mm by default: the sheet over a brain sunk
/// 15-20 mm lies 4-6 mm deep); around a resected tumour (within the spatial channels' saturation of
/// where the rigid prior puts it) only within the cavity's (3 mm): the cavity's fluid and the
/// gap's are one body there, and the long reach took the tissue around the cavity (on the
/// full-size scenarios the resections at 15-20 mm lost 0.02-0.06 mm mean with it). On this grid of
/// 5 mm slices every reach is at least a slice, and 3 and 6 mm join the same (measured): the two
/// reaches are 5 and 12 mm here.
void checkGapAndCavityReach(const testing::ClassifiedCase& c, TissueClassificationParameters p)
{
  auto joinedMl = [&c](const TissueClassificationParameters& q) {
    return classifyTissues(*c.simulated.intraopImage, *c.simulated.preopLabels, *c.rigid, std::nullopt, q).fluidJoinedToGapsMl;
  };
  p.gapReachMm = 12.0;
  p.cavityReachMm = 5.0;
  const double longMl = joinedMl(p);
  TissueClassificationParameters shortReach = p;
  shortReach.gapReachMm = shortReach.cavityReachMm;
  const double shortMl = joinedMl(shortReach);
  TissueClassificationParameters resected = p;
  resected.tumourResection = TumourResection::Resected;
  const double withCavityMl = joinedMl(resected);
  resected.cavityReachMm = resected.gapReachMm;
  const double cavityAsGapMl = joinedMl(resected);
  std::cout << "  joined within " << p.gapReachMm << " mm " << longMl << " ml, within " << shortReach.gapReachMm << " mm " << shortMl
            << " ml; tumour resected: " << withCavityMl << " ml, the cavity reaching as the gap " << cavityAsGapMl << " ml\n";
  BS_CHECK_MSG(longMl > shortMl, longMl << " against " << shortMl << " ml");
  BS_CHECK_MSG(withCavityMl < cavityAsGapMl, withCavityMl << " against " << cavityAsGapMl << " ml");
}
} // namespace

int TissueClassificationSunkenGapTest(int, char*[])
{
  return brainshift::testing::runTest("TissueClassificationSunkenGapTest", [] {
    using namespace brainshift;
    for (const char* name : {"rf20-lowfield", "lp20-cavityrim"}) {
      CaseParameters parameters = caseScenario(name).parameters;
      parameters.size = CaseSize::Small;
      testing::ClassifiedCase c{simulateCase(parameters), nullptr};
      c.rigid = registerRigidly(*c.simulated.intraopImage, *c.simulated.preopImage, c.simulated.preopLabels, {}).intraopToPreop;
      TissueClassificationParameters p;
      p.preopTumourContrast = preoperativeTumourContrast(*c.simulated.preopImage, *c.simulated.preopLabels);
      double gapMl[2] = {0, 0};
      testing::Scores scores[2];
      for (bool inAlignedBrain : {false, true}) {
        p.fluidThicknessInAlignedBrain = p.tumourFluidByLook = inAlignedBrain;
        const TissueClassificationResult r = classifyTissues(*c.simulated.intraopImage, *c.simulated.preopLabels, *c.rigid, std::nullopt, p);
        gapMl[inAlignedBrain] = gapTakenForBrainMl(*r.labels, c.simulated);
        scores[inAlignedBrain] = testing::scoresOf(*r.labels, c.simulated, inAlignedBrain ? "over the aligned brain too" : "over the k-NN's brain");
        std::cout << name << (inAlignedBrain ? " (aligned brain too)" : " (k-NN brain alone)") << ": gap taken for brain "
                  << gapMl[inAlignedBrain] << " ml, tumour resected " << r.tumourResected << "\n";
      }
      // Measured (small size, 2.5 x 2.5 x 5 mm): 16.3 and 16.1 ml of gap taken for brain over the
      // k-NN's brain alone, 10.5 and 10.6 ml with the aligned brain (and the tumour's look) too
      // (14.1 and 14.2 before the opening reached back across a 5 mm slice).
      BS_CHECK_MSG(gapMl[1] < 15.0, name << ": " << gapMl[1] << " ml of the gap taken for brain");
      BS_CHECK_MSG(gapMl[1] < gapMl[0] - 1.0, name << ": " << gapMl[1] << " against " << gapMl[0] << " ml");
      // Nothing else lost: the brain's overlap and boundary distance are no worse.
      BS_CHECK_MSG(scores[1].brain >= scores[0].brain - 1e-4, scores[1].brain << " against " << scores[0].brain);
      BS_CHECK_MSG(scores[1].surfaceMm <= scores[0].surfaceMm + 1e-3, scores[1].surfaceMm << " against " << scores[0].surfaceMm);

      // With the preoperative image the gap also takes the fluid next to it that was brain before
      // it sank (the sheet over the sunken brain, too thin on thick slices for the opening).
      takePreoperativeImage(p, *c.simulated.preopImage, *c.simulated.preopLabels, *c.rigid);
      const TissueClassificationResult joined = classifyTissues(*c.simulated.intraopImage, *c.simulated.preopLabels, *c.rigid, std::nullopt, p);
      const double joinedGapMl = gapTakenForBrainMl(*joined.labels, c.simulated);
      const testing::Scores joinedScores = testing::scoresOf(*joined.labels, c.simulated, "the gap joined by the fluid next to it");
      std::cout << name << " (fluid joined to the gap): gap taken for brain " << joinedGapMl << " ml, "
                << joined.fluidJoinedToGapsMl << " ml joined\n";
      BS_CHECK_MSG(joined.fluidJoinedToGapsMl > 0.0, joined.fluidJoinedToGapsMl);
      // Measured: 5.3 and 7.3 ml (6.3 and 5.3 ml joined).
      BS_CHECK_MSG(joinedGapMl < gapMl[1] - 2.0, name << ": " << joinedGapMl << " against " << gapMl[1] << " ml");
      BS_CHECK_MSG(joinedScores.brain >= scores[1].brain, joinedScores.brain << " against " << scores[1].brain);
      checkGapAndCavityReach(c, p);
      p.preopLook.reset();
    }
    // Where the fluid is brighter than the parenchyma (T2) the aligned brain is not used: the head
    // the k-NN finds inside it is mostly bright cortex, and counted as fluid it carved parenchyma
    // out of the brain. The labels are those of the k-NN's brain alone.
    CaseParameters t2 = caseScenario("rf10-t2").parameters;
    t2.size = CaseSize::Small;
    testing::ClassifiedCase c{simulateCase(t2), nullptr};
    c.rigid = registerRigidly(*c.simulated.intraopImage, *c.simulated.preopImage, c.simulated.preopLabels, {}).intraopToPreop;
    TissueClassificationParameters p;
    p.preopTumourContrast = preoperativeTumourContrast(*c.simulated.preopImage, *c.simulated.preopLabels);
    const TissueClassificationResult withDefaults = classifyTissues(*c.simulated.intraopImage, *c.simulated.preopLabels, *c.rigid, std::nullopt, p);
    BS_CHECK(withDefaults.contrast.fluidBrighterThanParenchyma());
    p.fluidThicknessInAlignedBrain = p.tumourFluidByLook = false;
    const TissueClassificationResult alone = classifyTissues(*c.simulated.intraopImage, *c.simulated.preopLabels, *c.rigid, std::nullopt, p);
    const LabelPixel* a = withDefaults.labels->GetBufferPointer();
    const LabelPixel* b = alone.labels->GetBufferPointer();
    std::size_t differing = 0;
    for (std::size_t i = 0, n = alone.labels->GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) differing += a[i] != b[i];
    const double brainDice = testing::scoresOf(*withDefaults.labels, c.simulated, "T2, the defaults").brain;
    std::cout << "T2: " << differing << " voxels differ from the k-NN's brain alone\n";
    BS_CHECK_MSG(differing == 0, differing << " voxels differ");
    BS_CHECK_MSG(brainDice > 0.95, brainDice);
    // Given the preoperative image, as the product runs: no fluid joined to the gaps in T2 (grown
    // through the bright cortex they took 15.6 ml of it here, brain Dice 0.956 -> 0.950).
    p.fluidThicknessInAlignedBrain = p.tumourFluidByLook = true;
    takePreoperativeImage(p, *c.simulated.preopImage, *c.simulated.preopLabels, *c.rigid);
    const TissueClassificationResult withImage = classifyTissues(*c.simulated.intraopImage, *c.simulated.preopLabels, *c.rigid, std::nullopt, p);
    const double withImageDice = testing::scoresOf(*withImage.labels, c.simulated, "T2, given the preoperative image").brain;
    BS_CHECK_MSG(withImage.fluidJoinedToGapsMl == 0.0, withImage.fluidJoinedToGapsMl << " ml joined in T2");
    BS_CHECK_MSG(withImageDice >= brainDice - 0.002, withImageDice << " against " << brainDice);
    // Labels on another grid than the image (the contract allows it): the image is read at the
    // labels' voxels. Here the intraoperative image stands in for one on a coarser grid: its
    // medians over the ventricles and the parenchyma are finite and in T2 order (fluid brighter).
    TissueClassificationParameters other;
    takePreoperativeImage(other, *c.simulated.intraopImage, *c.simulated.preopLabels, *c.rigid);
    const PreoperativeFluidAndParenchyma& m = other.preopLook->medians;
    std::cout << "labels on another grid: fluid " << m.fluid << ", parenchyma " << m.parenchyma << "\n";
    BS_CHECK_MSG(std::isfinite(m.fluid) && std::isfinite(m.parenchyma) && m.fluid > m.parenchyma, m.fluid << ", " << m.parenchyma);
  });
}
