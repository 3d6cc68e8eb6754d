// The trust assessment on a synthetic head: a brain (grey rim, white core, a ventricle, texture)
// that sank 4 mm inside a fixed skull. The update that moves it back scores above the rigid
// transform alone and is trusted; the one that moves it the wrong way scores below and is rejected;
// both also when the intraoperative scan has another, non-monotonic contrast (fluid bright, white
// matter dark, as in a T2) and noise. The stages' figures (freed nodes, folding) reject on their own.
// A small loss where the update moves the brain against a clear gain inside it is doubtful. The
// moved region is the brain's, though the field moves the fluid and bone around it too.
#include "BrainShiftTestingSupport.h"
#include "NonrigidUpdateTrust.h"
#include "SyntheticData.h"

#include <cmath>
#include <random>

namespace {
using namespace brainshift;
using brainshift::testing::grid;
using brainshift::testing::imageOn;
using brainshift::testing::point;

const double SinkMm = 4.0; // the brain sinks along -z (inferior, LPS)

double skull(const PhysicalPoint& p)
{
  const double r = p.GetVectorFromOrigin().GetNorm();
  return r > 27 && r < 31 ? 0.3 : r <= 27 ? 0.1 : 0.0; // bone; fluid inside, where the brain is not
}

double brain(const PhysicalPoint& p) // the brain at rest, centred at the origin
{
  const double r = p.GetVectorFromOrigin().GetNorm();
  if (r > 22) return -1;
  const double ventricle = std::pow(p[0] / 6, 2) + std::pow(p[1] / 10, 2) + std::pow((p[2] - 3) / 4, 2);
  if (ventricle < 1) return 0.1;
  const double texture = 0.06 * std::sin(p[0] / 2.5) * std::cos(p[1] / 3.0) * std::sin(p[2] / 2.0);
  return (r > 18.5 ? 0.6 : 0.9) + texture;
}

/// The head with the brain displaced by `brainOffsetZ` mm along z.
double head(const PhysicalPoint& p, double brainOffsetZ)
{
  PhysicalPoint q = p;
  q[2] -= brainOffsetZ;
  const double b = brain(q);
  return b >= 0 ? b : skull(p);
}

/// A T2-like remapping: fluid bright, white matter dark, bone dark (not monotonic in the T1 value).
double t2Like(double t1)
{
  if (t1 < 0.05) return 0.0;
  if (t1 < 0.2) return 1.0;  // fluid
  if (t1 < 0.45) return 0.15; // bone
  if (t1 < 0.75) return 0.6;  // grey
  return 0.35 + (t1 - 0.9);   // white matter, its texture kept
}

ScalarImage::Pointer intraopScan(const ImageGeometry& g, bool otherContrast)
{
  std::mt19937 random(7);
  std::normal_distribution<double> noise(0.0, 0.03);
  return imageOn<ScalarImage>(g, [&](const PhysicalPoint& p) {
    const double t1 = head(p, -SinkMm);
    return float((otherContrast ? t2Like(t1) : t1) + noise(random));
  });
}

LabelImage::Pointer labelsOf(const ImageGeometry& g, double brainOffsetZ)
{
  return imageOn<LabelImage>(g, [&](const PhysicalPoint& p) {
    PhysicalPoint q = p;
    q[2] -= brainOffsetZ;
    return LabelPixel(brain(q) >= 0 ? 2 : skull(p) > 0 ? 1 : 0);
  });
}

DisplacementFieldImage::Pointer constantField(const ImageGeometry& g, double dz)
{
  return imageOn<DisplacementFieldImage>(g, [&](const PhysicalPoint&) {
    DisplacementVector v;
    v[0] = 0;
    v[1] = 0;
    v[2] = float(dz);
    return v;
  });
}

/// The assessment of an update that displaces the preoperative brain by `updateOffsetZ` on the
/// intraoperative grid (the right update: -SinkMm), against the rigid transform (the identity here).
NonrigidUpdateTrustAssessment assess(const ImageGeometry& g, bool otherContrast, double updateOffsetZ,
                                     NonrigidUpdateTrustInputs extra = {}, const NonrigidUpdateTrustParameters& parameters = {})
{
  const ScalarImage::Pointer intraop = intraopScan(g, otherContrast);
  const ScalarImage::Pointer byUpdate = imageOn<ScalarImage>(g, [&](const PhysicalPoint& p) { return float(head(p, updateOffsetZ)); });
  const ScalarImage::Pointer byRigid = imageOn<ScalarImage>(g, [&](const PhysicalPoint& p) { return float(head(p, 0)); });
  const LabelImage::Pointer intraopLabels = labelsOf(g, -SinkMm), labelsByUpdate = labelsOf(g, updateOffsetZ),
                            labelsByRigid = labelsOf(g, 0);
  const DisplacementFieldImage::Pointer updateField = constantField(g, -updateOffsetZ), rigidField = constantField(g, 0);
  NonrigidUpdateTrustInputs in = extra;
  in.intraop = intraop.GetPointer();
  in.warpedByUpdate = byUpdate.GetPointer();
  in.warpedByRigid = byRigid.GetPointer();
  in.intraopLabels = intraopLabels.GetPointer();
  in.labelsWarpedByUpdate = labelsByUpdate.GetPointer();
  in.labelsWarpedByRigid = labelsByRigid.GetPointer();
  in.updateField = updateField.GetPointer();
  in.rigidField = rigidField.GetPointer();
  return assessNonrigidUpdate(in, parameters);
}
} // namespace

int NonrigidUpdateTrustTest(int, char*[])
{
  return brainshift::testing::runTest("NonrigidUpdateTrustTest", [] {
    // eta^2: 1 for any function of the predictor (an inverted one too), near 0 for unrelated values.
    std::vector<float> predictor, inverted, unrelated;
    std::mt19937 random(3);
    std::uniform_real_distribution<float> uniform(0, 1);
    for (int i = 0; i < 4000; ++i) {
      predictor.push_back(float(i % 8));
      inverted.push_back(10.0f - float(i % 8) * float(i % 8));
      unrelated.push_back(uniform(random));
    }
    BS_CHECK_NEAR(correlationRatio(inverted, predictor, 8, 0, 8), 1.0, 1e-9);
    BS_CHECK(correlationRatio(unrelated, predictor, 8, 0, 8) < 0.01);
    BS_CHECK(correlationRatio(std::vector<float>(10, 1.0f), std::vector<float>(10, 2.0f), 8, 0, 8) == 0.0);

    const ImageGeometry g = grid({{44, 44, 44}}, {{1.5, 1.5, 1.5}}, point(-32.25, -32.25, -32.25));
    for (const bool otherContrast : {false, true}) {
      const NonrigidUpdateTrustAssessment right = assess(g, otherContrast, -SinkMm);
      const NonrigidUpdateTrustAssessment wrong = assess(g, otherContrast, +SinkMm);
      const char* contrast = otherContrast ? "T2-like" : "T1";
      BS_CHECK_MSG(right.band.gain() > 0.05, contrast << ": right update gains " << right.band.gain() << " near the boundary");
      BS_CHECK_MSG(right.moved.gain() > 0.05, contrast << ": right update gains " << right.moved.gain() << " where it moves");
      BS_CHECK_MSG(right.trust == UpdateTrust::Trusted, contrast << ": " << trustName(right.trust));
      BS_CHECK(right.reasons.empty());
      BS_CHECK_MSG(wrong.band.gain() < -0.05, contrast << ": wrong update gains " << wrong.band.gain() << " near the boundary");
      BS_CHECK_MSG(wrong.moved.nonrigid < right.moved.nonrigid, contrast);
      BS_CHECK_MSG(wrong.trust == UpdateTrust::Rejected, contrast << ": " << trustName(wrong.trust));
      BS_CHECK(!wrong.reasons.empty() && wrong.reasons.front().find("worse than the rigid result") != std::string::npos);
      BS_CHECK(right.moved.voxels > 1000 && right.band.voxels > right.moved.voxels / 4 && right.interior.voxels > 1000);
      // The field moves every voxel by 4 mm, but the moved region is the brain's: the voxels the
      // scan or the update shows as brain (here the same), not the fluid and bone around it.
      const LabelImage::Pointer sunk = labelsOf(g, -SinkMm);
      std::size_t brainVoxels = 0;
      for (std::size_t i = 0; i < g.numberOfVoxels(); ++i) brainVoxels += sunk->GetBufferPointer()[i] == 2;
      BS_CHECK_MSG(right.moved.voxels <= brainVoxels && right.moved.voxels > brainVoxels / 2,
                   right.moved.voxels << " moved voxels, " << brainVoxels << " of brain");
    }

    // The surface stage's and the field's figures reject a update the image would accept.
    NonrigidUpdateTrustInputs freed;
    freed.surfaceNodes = 1000;
    freed.unmatchedSurfaceNodes = 400;
    const NonrigidUpdateTrustAssessment manyFreed = assess(g, false, -SinkMm, freed);
    BS_CHECK(manyFreed.trust == UpdateTrust::Rejected);
    BS_CHECK_NEAR(manyFreed.unmatchedShare, 0.4, 1e-12);
    BS_CHECK(manyFreed.reasons.size() == 1 && manyFreed.reasons[0].find("40 % of the surface nodes") != std::string::npos);
    NonrigidUpdateTrustInputs folded;
    folded.foldedVoxels = 500;
    folded.meshVoxels = 10000;
    BS_CHECK(assess(g, false, -SinkMm, folded).trust == UpdateTrust::Rejected);
    folded.foldedVoxels = 100;
    BS_CHECK(assess(g, false, -SinkMm, folded).trust == UpdateTrust::Doubtful);
    folded.foldedVoxels = 1; // a voxel or two fold in good updates as well
    BS_CHECK(assess(g, false, -SinkMm, folded).trust == UpdateTrust::Trusted);

    // Mixed evidence: a small loss where the update moves the brain (here: the thresholds moved above
    // the right update's own gain, so that its gain counts as a loss) with a clear gain inside the
    // brain is doubtful, not rejected; without the gain inside, or with a larger loss, rejected.
    {
      const NonrigidUpdateTrustAssessment right = assess(g, false, -SinkMm);
      const double movedGain = right.moved.gain(), interiorGain = right.interior.gain();
      BS_CHECK_MSG(interiorGain > 0.01, "the right update gains " << interiorGain << " inside the brain");
      NonrigidUpdateTrustParameters mixed;
      mixed.rejectGainBelow = movedGain + 0.01;
      mixed.doubtGainBelow = movedGain + 0.02;
      mixed.mixedLossDownTo = movedGain - 0.01;
      mixed.mixedInteriorGainFrom = interiorGain - 0.001;
      const NonrigidUpdateTrustAssessment doubtful = assess(g, false, -SinkMm, {}, mixed);
      BS_CHECK_MSG(doubtful.trust == UpdateTrust::Doubtful, trustName(doubtful.trust));
      BS_CHECK(doubtful.reasons.size() == 1 && doubtful.reasons[0].find("but better inside the brain") != std::string::npos);
      NonrigidUpdateTrustParameters noGainInside = mixed;
      noGainInside.mixedInteriorGainFrom = interiorGain + 0.001;
      BS_CHECK(assess(g, false, -SinkMm, {}, noGainInside).trust == UpdateTrust::Rejected);
      NonrigidUpdateTrustParameters largerLoss = mixed;
      largerLoss.mixedLossDownTo = movedGain + 0.005;
      const NonrigidUpdateTrustAssessment rejected = assess(g, false, -SinkMm, {}, largerLoss);
      BS_CHECK(rejected.trust == UpdateTrust::Rejected && rejected.reasons[0].find("worse than the rigid result") != std::string::npos);
    }

    // Images off the intraoperative grid are refused.
    const ImageGeometry other = grid({{40, 44, 44}}, {{1.5, 1.5, 1.5}}, point(-32.25, -32.25, -32.25));
    const ScalarImage::Pointer small = imageOn<ScalarImage>(other, [](const PhysicalPoint&) { return 0.0f; });
    const ScalarImage::Pointer intraop = intraopScan(g, false);
    NonrigidUpdateTrustInputs offGrid;
    offGrid.intraop = intraop.GetPointer();
    offGrid.warpedByUpdate = small.GetPointer();
    offGrid.warpedByRigid = intraop.GetPointer();
    const LabelImage::Pointer labels = labelsOf(g, 0);
    offGrid.intraopLabels = labels.GetPointer();
    BS_CHECK_THROWS(assessNonrigidUpdate(offGrid), std::invalid_argument, "not on the intraoperative grid");
  });
}
