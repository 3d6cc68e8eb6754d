// The truth of the built-in case, checked against what the images show (not only against the
// landmarks, which are made through the truth): the true transform brings the preoperative labels
// and intensities onto the intraoperative scan, and the identity does not.
#include "BrainShiftTestingSupport.h"
#include "CaseSimulationTestSupport.h"
#include "LandmarkEvaluation.h"

#include <itkIdentityTransform.h>
#include <itkImageRegionConstIteratorWithIndex.h>

#include <cmath>
#include <iostream>
#include <set>

namespace {
using namespace brainshift;

struct Agreement {
  double labelAgreement = 0; ///< fraction of deep intraop brain voxels whose preop label matches
  double correlation = 0;    ///< of intraop and preop intensity over those voxels
  std::size_t voxels = 0;
};

/// Compares the intraop scan with the preop data pulled back through `transform`, over the brain
/// tissue that moved: intraop parenchyma and ventricles where the truth and its rigid part differ
/// by more than 3 mm.
Agreement agreementThrough(const SimulatedCase& c, const SpatialTransform& transform)
{
  const LabelImage* truth = c.intraopLabels;
  std::size_t same = 0, total = 0;
  double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
  itk::ImageRegionConstIteratorWithIndex<LabelImage> it(truth, truth->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    if (it.Get() != 2 && it.Get() != 3) continue;
    PhysicalPoint y;
    truth->TransformIndexToPhysicalPoint(it.GetIndex(), y);
    if (c.intraopToPreop->TransformPoint(y).EuclideanDistanceTo(c.rigidIntraopToPreop->TransformPoint(y)) < 3.0) continue;
    const PhysicalPoint x = transform.TransformPoint(y);
    LabelImage::IndexType preopIndex;
    if (!c.preopLabels->TransformPhysicalPointToIndex(x, preopIndex)) continue;
    ++total;
    same += c.preopLabels->GetPixel(preopIndex) == it.Get();
    const double a = c.intraopImage->GetPixel(it.GetIndex()), b = c.preopImage->GetPixel(preopIndex);
    sx += a; sy += b; sxx += a * a; syy += b * b; sxy += a * b;
  }
  Agreement agreement;
  const double n = double(total);
  agreement.voxels = total;
  agreement.labelAgreement = double(same) / n;
  agreement.correlation = (sxy / n - sx / n * sy / n) /
                          std::sqrt((sxx / n - sx / n * sx / n) * (syy / n - sy / n * sy / n));
  return agreement;
}

std::set<LabelPixel> labelsIn(const LabelImage* image)
{
  std::set<LabelPixel> present;
  const LabelPixel* p = image->GetBufferPointer();
  for (std::size_t i = 0, n = image->GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) present.insert(p[i]);
  return present;
}
} // namespace

int CaseSimulationTruthTest(int, char*[])
{
  return brainshift::testing::runTest("CaseSimulationTruthTest", [] {
    using namespace brainshift;
    const SimulatedCase& c = testing::smallCase();
    const CaseFigures& f = c.figures;

    // The shift model: peak sinking as asked, a gap and a cavity, no folding.
    BS_CHECK_MSG(f.maxBrainDisplacementMm > 9.0 && f.maxBrainDisplacementMm <= 10.0 + 1e-6, f.maxBrainDisplacementMm);
    BS_CHECK_MSG(f.gapVolumeMl > 5.0, f.gapVolumeMl);
    BS_CHECK_MSG(f.cavityVolumeMl > 2.0, f.cavityVolumeMl);
    BS_CHECK_MSG(f.minJacobianDeterminant > 0.5, f.minJacobianDeterminant);
    BS_CHECK_MSG(!foldedTruthWarning(f), *foldedTruthWarning(f)); // a truth that does not fold: no warning
    // One that folds is said to, with its figures (lp15-fe-superficial-intact's).
    CaseFigures folded = f;
    folded.truthFoldedElements = 94;
    folded.truthElements = 18270;
    folded.minJacobianDeterminant = -1.6;
    const std::optional<std::string> folds = foldedTruthWarning(folded);
    BS_CHECK(folds && folds->find("down to -1.6 in the brain, 94 of its 18270 finite elements inverted") != std::string::npos &&
             folds->find("ill-defined") != std::string::npos);
    folded.truthFoldedElements = 0; // a kinematic truth whose determinant is not positive
    folded.minJacobianDeterminant = 0;
    BS_CHECK(foldedTruthWarning(folded) && foldedTruthWarning(folded)->find("elements inverted") == std::string::npos);
    folded.truthFoldedElements = 15; // elements a linear solve inverted, the field not folding (rf10-fe-sliding)
    folded.minJacobianDeterminant = 0.2;
    BS_CHECK(!foldedTruthWarning(folded));
    BS_CHECK_MSG(f.tumourVolumeMl > 3.0 && f.tumourVolumeMl < 10.0, f.tumourVolumeMl);
    BS_CHECK_MSG(f.ventricleVolumeMl > 5.0 && f.ventricleVolumeMl < 40.0, f.ventricleVolumeMl);

    // Anatomy: a right frontal craniotomy is on the patient's right (LPS x < 0), anterior of the
    // anterior commissure (Colin27's origin: y < 0) and superior.
    BS_CHECK_MSG(f.craniotomyCentre[0] < -15 && f.craniotomyCentre[1] < 0 && f.craniotomyCentre[2] > 20,
                 f.craniotomyCentre);

    // Labels: the five of the contract before surgery; the tumour is gone after the resection.
    const std::set<LabelPixel> all{0, 1, 2, 3, 4};
    BS_CHECK(labelsIn(c.preopLabels) == all);
    BS_CHECK((labelsIn(c.intraopLabels) == std::set<LabelPixel>{0, 1, 2, 3}));
    BS_CHECK(labelsIn(testing::smallCase(false).intraopLabels) == all);

    // The truth maps the images onto each other; identity and the rigid part alone do worse.
    auto identity = itk::IdentityTransform<double, 3>::New();
    const Agreement truth = agreementThrough(c, *c.intraopToPreop);
    const Agreement none = agreementThrough(c, *identity);
    const Agreement rigidOnly = agreementThrough(c, *c.rigidIntraopToPreop);
    std::cout << truth.voxels << " moved voxels; label agreement / intensity correlation: truth " << truth.labelAgreement << " / " << truth.correlation
              << ", rigid part only " << rigidOnly.labelAgreement << " / " << rigidOnly.correlation << ", identity "
              << none.labelAgreement << " / " << none.correlation << '\n';
    BS_CHECK_MSG(truth.voxels > 500, truth.voxels);
    BS_CHECK_MSG(truth.labelAgreement > 0.95, truth.labelAgreement);
    BS_CHECK_MSG(truth.correlation > 0.75, truth.correlation);
    BS_CHECK_MSG(rigidOnly.correlation < truth.correlation - 0.1, rigidOnly.correlation << " vs " << truth.correlation);
    BS_CHECK_MSG(none.correlation < truth.correlation - 0.2, none.correlation << " vs " << truth.correlation);

    // Landmarks: the truth's error is about zero, the identity's about the shift plus the motion.
    const RegistrationError exact = evaluateTransform(*c.intraopToPreop, c.landmarks);
    const RegistrationError identityError = evaluateTransform(*identity, c.landmarks);
    const RegistrationError rigidError = evaluateTransform(*c.rigidIntraopToPreop, c.landmarks);
    BS_CHECK_MSG(exact.overall.maxMm < 0.02, exact.overall.maxMm);
    BS_CHECK_MSG(identityError.overall.meanMm > 8.0, identityError.overall.meanMm);
    for (const char* group : {"craniotomy", "near-cavity", "brain", "head"}) {
      BS_CHECK_MSG(exact.groups.count(group) && exact.groups.at(group).count >= 4, group);
    }
    // The rigid part alone is exact on the head and off by about the shift under the craniotomy.
    BS_CHECK_MSG(rigidError.groups.at("head").maxMm < 0.02, rigidError.groups.at("head").maxMm);
    BS_CHECK_MSG(rigidError.groups.at("craniotomy").meanMm > 3.0, rigidError.groups.at("craniotomy").meanMm);
    // Every landmark lies inside the intraoperative field of view.
    for (const LandmarkPair& pair : c.landmarks) {
      LabelImage::IndexType index;
      BS_CHECK_MSG(c.intraopLabels->TransformPhysicalPointToIndex(pair.intraop, index), pair.name);
    }
  });
}
