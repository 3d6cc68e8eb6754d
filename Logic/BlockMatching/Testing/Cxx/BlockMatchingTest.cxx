// Block matching on an analytic texture of known motion: the tissue moved by a known translation,
// seen through a rigid transform and an inverted (T2-like) contrast with noise.
// - the matches recover the translation (median error below a quarter of a voxel), through the
//   inverted contrast (the remap learned from the scan makes the correlation positive);
// - a prediction 4 mm off is corrected within the search window;
// - blocks whose match falls in a cavity of the scan are dropped, none is kept there;
// - blocks holding an excluded tissue (a resected tumour) are not matched;
// - a flat region of the scan (one grey level, no noise: a fluid-filled cavity's signal void) is
//   no match for anything, and no correlation exceeds 1 (the windows' sums slide, and a flat
//   window's residue of rounding must not pass for variance);
// - a refine pass's new classification: the earlier matches whose block it no longer calls brain
//   are dropped, the others kept as they were;
// - the selection spread over the brain: where half the brain has a tenth of the contrast, the
//   most structured blocks all lie in the other half; spread over 8 mm cubes, every cube gets a
//   block before any gets a second, half of them lie in the faint half, and match there;
// - under a strong shear (the brain sinking beside tissue that stays), with the prediction's
//   displacement and gradient exact: translated windows match worse (lower correlations, larger
//   errors) than the windows the prediction deforms, which the blocks then take; without the
//   gradient (or without the option) the matching is the translated one, match for match;
// - through heavy noise, both images smoothed (a Gaussian of 0.7 mm) match with a smaller error;
//   without noise no worse; one noisy image on both sides, smoothed alike, correlates fully;
// - absurd parameters are refused.
#include "BlockMatching.h"
#include "BrainShiftTestingSupport.h"
#include "SyntheticData.h"

#include <itkEuler3DTransform.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <iostream>
#include <random>

namespace {
using namespace brainshift;

/// A texture without a period in the search window: cosines of wavelengths 6 to 17 mm.
double texture(const PhysicalPoint& p)
{
  const double k[6][3] = {{0.9, 0.3, 0.1}, {-0.2, 0.7, 0.4}, {0.3, -0.4, 0.8}, {0.5, 0.5, -0.5}, {-0.6, 0.2, 0.5}, {0.1, -0.8, -0.3}};
  const double phase[6] = {0.3, 1.1, 2.0, 0.7, 2.9, 1.6};
  double v = 0;
  for (int i = 0; i < 6; ++i) v += std::cos(k[i][0] * p[0] + k[i][1] * p[1] + k[i][2] * p[2] + phase[i]) / (1 + 0.3 * i);
  return 100 + 30 * v;
}

double distance(const PhysicalPoint& p, const std::array<double, 3>& c)
{
  return std::sqrt((p[0] - c[0]) * (p[0] - c[0]) + (p[1] - c[1]) * (p[1] - c[1]) + (p[2] - c[2]) * (p[2] - c[2]));
}

/// Each match's distance from the true displacement `shift`, ascending.
std::vector<double> sortedErrors(const BlockMatchingResult& result, const std::array<double, 3>& shift)
{
  std::vector<double> errors;
  for (const BlockMatch& m : result.matches) {
    errors.push_back(std::hypot(m.displacement[0] - shift[0], m.displacement[1] - shift[1], m.displacement[2] - shift[2]));
  }
  std::sort(errors.begin(), errors.end());
  return errors;
}

/// A refine pass's new classification of the same scan (`notBrain`: where it calls the scan's
/// point not brain, a second cavity {12, 14, -8} of 9 mm beside the first): the earlier matches
/// held against it. Against the classification they were matched with they stay (but a few at the
/// brain share's bound: the check reads the scan's grid at the sub-voxel match, the matching its
/// own grid at the whole voxel); against the new one, those whose block lands in the second cavity
/// go, the others stay.
void checkMatchesHeldAgainstNewClassification(const BlockMatchingResult& result, const ScalarImage& preop, const LabelImage& intraopLabels,
                                              const SpatialTransform& rigid, const BlockMatchingParameters& parameters,
                                              const std::function<bool(const PhysicalPoint&)>& notBrain)
{
  const BlockMatchingResult same = matchesStillInBrain(result, preop, intraopLabels, rigid, parameters);
  BS_CHECK_MSG(same.matches.size() >= result.matches.size() * 99 / 100, same.matches.size() << " of " << result.matches.size());
  const LabelImage::Pointer reclassified =
    testing::imageOn<LabelImage>(ImageGeometry::of(&intraopLabels), [&](const PhysicalPoint& y) { return LabelPixel(notBrain(y) ? 0 : 2); });
  const std::array<double, 3> secondCavity{12, 14, -8};
  const BlockMatchingResult held = matchesStillInBrain(result, preop, *reclassified, rigid, parameters);
  auto target = [](const BlockMatch& m) {
    PhysicalPoint x = m.centre;
    for (int a = 0; a < 3; ++a) x[a] += m.displacement[std::size_t(a)];
    return x;
  };
  std::size_t inSecondCavity = 0, droppedFarFromIt = 0;
  for (const BlockMatch& m : held.matches) inSecondCavity += distance(target(m), secondCavity) < 6;
  for (const BlockMatch& m : result.matches) {
    const bool kept = std::any_of(held.matches.begin(), held.matches.end(), [&](const BlockMatch& k) { return k.centre == m.centre; });
    if (!kept && distance(target(m), secondCavity) > 9 + 2 * parameters.blockHalfSizeMm) ++droppedFarFromIt;
  }
  const std::size_t dropped = result.matches.size() - held.matches.size();
  std::cout << "held against a classification with a second cavity: " << held.matches.size() << " of " << result.matches.size()
            << " kept, " << held.outsideBrain - result.outsideBrain << " now outside the brain\n";
  BS_CHECK_MSG(dropped >= 5, dropped);
  BS_CHECK_MSG(inSecondCavity == 0, inSecondCavity);
  BS_CHECK_MSG(droppedFarFromIt <= result.matches.size() - same.matches.size(), droppedFarFromIt); // the bound's few
}

/// A brain whose left half (x < 0) carries the texture at full contrast and whose right half at a
/// tenth of it (white matter beside the cortex's folds), moved by a known shift, a quarter of the
/// candidates matched. By structure alone the blocks all go to the left; spread over 8 mm cubes, as
/// many lie right as left, and they match there too (a tenth of the contrast is still structure
/// against the noise). The order is the same on every call.
void checkSelectionSpreadOverTheBrain()
{
  const std::array<double, 3> shift{1.6, -2.2, 1.1};
  const ImageGeometry grid = testing::grid({{56, 56, 56}}, {1.5, 1.5, 1.5}, testing::point(-42, -42, -42));
  auto halves = [](const PhysicalPoint& p) { return 100 + (p[0] < 0 ? 1.0 : 0.1) * (texture(p) - 100); };
  const ScalarImage::Pointer preop = testing::imageOn<ScalarImage>(grid, [&](const PhysicalPoint& p) { return float(halves(p)); });
  const LabelImage::Pointer labels = testing::imageOn<LabelImage>(grid, [](const PhysicalPoint& p) { return LabelPixel(distance(p, {0, 0, 0}) > 36 ? 0 : 2); });
  std::mt19937_64 rng(11);
  std::normal_distribution<double> noise(0.0, 0.5);
  const ScalarImage::Pointer scan = testing::imageOn<ScalarImage>(grid, [&](const PhysicalPoint& y) {
    return float(halves(testing::point(y[0] - shift[0], y[1] - shift[1], y[2] - shift[2])) + noise(rng));
  });
  const LabelImage::Pointer scanLabels = testing::imageOn<LabelImage>(grid, [&](const PhysicalPoint& y) {
    return LabelPixel(distance(testing::point(y[0] - shift[0], y[1] - shift[1], y[2] - shift[2]), {0, 0, 0}) > 36 ? 0 : 2);
  });
  auto identity = itk::Euler3DTransform<double>::New();
  BlockMatchingParameters parameters;
  parameters.blockSpacingMm = 4;
  parameters.selectedShare = 0.25;
  const DisplacementPrediction none;
  auto rightShare = [](const BlockMatchingResult& r) {
    std::size_t right = 0;
    for (const BlockMatch& m : r.matches) right += m.centre[0] > 0;
    return r.matches.empty() ? 0.0 : double(right) / double(r.matches.size());
  };
  const BlockMatchingResult byStructure = matchBlocks(*preop, *labels, *scan, *scanLabels, *identity, none, parameters);
  parameters.selectionCellMm = 8;
  const BlockMatchingResult spread = matchBlocks(*preop, *labels, *scan, *scanLabels, *identity, none, parameters);
  const BlockMatchingResult again = matchBlocks(*preop, *labels, *scan, *scanLabels, *identity, none, parameters);
  std::vector<double> rightErrors;
  for (const BlockMatch& m : spread.matches) {
    if (m.centre[0] > 4) rightErrors.push_back(std::hypot(m.displacement[0] - shift[0], m.displacement[1] - shift[1], m.displacement[2] - shift[2]));
  }
  std::sort(rightErrors.begin(), rightErrors.end());
  const double rightMedian = rightErrors.empty() ? 99 : rightErrors[rightErrors.size() / 2];
  std::cout << "selection: " << byStructure.selected << " of " << byStructure.candidates << " candidates; right half (a tenth of the contrast) "
            << rightShare(byStructure) << " of the matches by structure alone, " << rightShare(spread) << " spread over 8 mm cubes ("
            << spread.matches.size() << " matched, right of x = 4 mm error median " << rightMedian << " mm)\n";
  BS_CHECK_MSG(byStructure.selected == spread.selected, byStructure.selected << " vs " << spread.selected);
  // Every cube gets a block before any gets a second.
  std::cout << "  " << spread.selectionCells << " cubes hold candidates, " << spread.selectionCellsWithBlock << " a block\n";
  BS_CHECK_MSG(byStructure.selectionCells == 0 && spread.selectionCells > 0, byStructure.selectionCells << ", " << spread.selectionCells);
  BS_CHECK_MSG(spread.selectionCellsWithBlock == std::min(spread.selected, spread.selectionCells),
               spread.selectionCellsWithBlock << " of " << spread.selectionCells << " for " << spread.selected);
  BS_CHECK_MSG(rightShare(byStructure) < 0.05, rightShare(byStructure));
  BS_CHECK_MSG(rightShare(spread) > 0.35 && rightShare(spread) < 0.65, rightShare(spread));
  BS_CHECK_MSG(spread.matches.size() >= spread.selected * 8 / 10, spread.matches.size());
  BS_CHECK_MSG(rightMedian < 0.35, rightMedian);
  BS_CHECK_MSG(again.matches.size() == spread.matches.size(), again.matches.size());
  for (std::size_t m = 0; m < std::min(again.matches.size(), spread.matches.size()); ++m) {
    BS_CHECK_MSG(again.matches[m].centre == spread.matches[m].centre && again.matches[m].displacement == spread.matches[m].displacement, m);
  }
}
/// A shear of 0.45 (x moves 0.45 mm per mm of z, as under the edge of a craniotomy that sank)
/// and a translation, on an oblique grid of 1-1.3 mm: with the exact prediction, the deformed windows find what
/// remains (nothing, to the sub-voxel fit's precision) where the translated ones, their texture
/// sheared across the block, correlate less and err more.
void checkDeformedWindowsUnderShear()
{
  const double shear = 0.45;
  const std::array<double, 3> translation{1.0, -0.5, 0.8};
  auto displacement = [&](const PhysicalPoint& x) { return std::array<double, 3>{translation[0] + shear * x[2], translation[1], translation[2]}; };
  // Oblique and anisotropic, so that the gradient's passage into the grid's voxels (P G D S)
  // matters: the physical gradient taken for the voxels' would stretch the wrong axes.
  const ImageGeometry grid = testing::grid({{76, 70, 62}}, {1.0, 1.15, 1.3}, testing::point(-38, -40, -40), testing::rotationAbout(0.3, -0.4, 1.0, 25));
  const ScalarImage::Pointer preop = testing::imageOn<ScalarImage>(grid, [](const PhysicalPoint& p) { return float(texture(p)); });
  const LabelImage::Pointer labels = testing::imageOn<LabelImage>(grid, [](const PhysicalPoint& p) { return LabelPixel(distance(p, {0, 0, 0}) > 30 ? 0 : 2); });
  auto source = [&](const PhysicalPoint& y) { // the preoperative point seen at y: y = x + u(x)
    const double z = y[2] - translation[2];
    return testing::point(y[0] - translation[0] - shear * z, y[1] - translation[1], z);
  };
  std::mt19937_64 rng(17);
  std::normal_distribution<double> noise(0.0, 1.0);
  const ScalarImage::Pointer scan = testing::imageOn<ScalarImage>(grid, [&](const PhysicalPoint& y) { return float(texture(source(y)) + noise(rng)); });
  const LabelImage::Pointer scanLabels =
    testing::imageOn<LabelImage>(grid, [&](const PhysicalPoint& y) { return LabelPixel(distance(source(y), {0, 0, 0}) > 30 ? 0 : 2); });
  auto identity = itk::Euler3DTransform<double>::New();
  const std::array<std::array<double, 3>, 3> gradient{{{0, 0, shear}, {0, 0, 0}, {0, 0, 0}}};
  const DisplacementPrediction exact = [&](const PhysicalPoint& x) { return PredictedDisplacement{displacement(x), gradient}; };
  const DisplacementPrediction withoutGradient = [&](const PhysicalPoint& x) { return PredictedDisplacement{displacement(x), std::nullopt}; };
  BlockMatchingParameters parameters;
  parameters.blockHalfSizeMm = 4.5;
  parameters.blockSpacingMm = 6;
  parameters.selectedShare = 1.0;
  parameters.minimumSimilarity = 0.2;
  parameters.largestPredictedMm = 15;
  const BlockMatchingResult translated = matchBlocks(*preop, *labels, *scan, *scanLabels, *identity, exact, parameters);
  parameters.deformedWindows = true;
  const BlockMatchingResult deformed = matchBlocks(*preop, *labels, *scan, *scanLabels, *identity, exact, parameters);
  const BlockMatchingResult noGradient = matchBlocks(*preop, *labels, *scan, *scanLabels, *identity, withoutGradient, parameters);
  struct Figures {
    double medianError = 99, meanSimilarity = 0;
  };
  auto figures = [&](const BlockMatchingResult& r) {
    Figures f;
    std::vector<double> errors;
    for (const BlockMatch& m : r.matches) {
      const std::array<double, 3> truth = displacement(m.centre);
      errors.push_back(std::hypot(m.displacement[0] - truth[0], m.displacement[1] - truth[1], m.displacement[2] - truth[2]));
      f.meanSimilarity += m.similarity / double(r.matches.size());
    }
    std::sort(errors.begin(), errors.end());
    if (!errors.empty()) f.medianError = errors[errors.size() / 2];
    return f;
  };
  const Figures t = figures(translated), d = figures(deformed);
  std::cout << "shear " << shear << ": translated windows " << translated.matches.size() << " of " << translated.selected << " matched, error median "
            << t.medianError << " mm, correlation mean " << t.meanSimilarity << "; deformed " << deformed.matches.size() << " matched, error median "
            << d.medianError << " mm, correlation mean " << d.meanSimilarity << "\n";
  BS_CHECK_MSG(translated.selected > 40, translated.selected);
  BS_CHECK_MSG(deformed.matches.size() >= deformed.selected * 9 / 10, deformed.matches.size() << " of " << deformed.selected);
  BS_CHECK_MSG(d.meanSimilarity > 0.9 && d.meanSimilarity > t.meanSimilarity + 0.1, d.meanSimilarity << " vs " << t.meanSimilarity);
  BS_CHECK_MSG(d.medianError < 0.2 && d.medianError < 0.5 * t.medianError, d.medianError << " vs " << t.medianError);
  BS_CHECK_MSG(noGradient.matches.size() == translated.matches.size(), noGradient.matches.size() << " vs " << translated.matches.size());
  for (std::size_t m = 0; m < std::min(noGradient.matches.size(), translated.matches.size()); ++m) {
    BS_CHECK_MSG(noGradient.matches[m].displacement == translated.matches[m].displacement, m);
  }
}

/// A translation seen through heavy noise on a 1 mm grid: both images smoothed by a Gaussian of
/// 0.7 mm, the matches err less (the noise moves the correlation's peak less); without noise they
/// err no more (the same kernel on both images keeps a translation a translation; what remains is
/// the sub-voxel fit's own error). One noisy image on both sides: both smoothed alike, every block
/// correlates fully where it lies.
void checkSmoothingAgainstNoise()
{
  const std::array<double, 3> shift{1.3, -0.6, 2.2};
  const ImageGeometry grid = testing::grid({{64, 64, 64}}, {1.0, 1.0, 1.0}, testing::point(-32, -32, -32));
  const ScalarImage::Pointer preop = testing::imageOn<ScalarImage>(grid, [](const PhysicalPoint& p) { return float(texture(p)); });
  const LabelImage::Pointer labels = testing::imageOn<LabelImage>(grid, [](const PhysicalPoint& p) { return LabelPixel(distance(p, {0, 0, 0}) > 26 ? 0 : 2); });
  auto source = [&](const PhysicalPoint& y) { return testing::point(y[0] - shift[0], y[1] - shift[1], y[2] - shift[2]); };
  auto scanWithNoise = [&](double sigma) { // sigma 0: none (a normal distribution needs a positive one)
    std::mt19937_64 rng(23);
    std::normal_distribution<double> noise(0.0, sigma > 0 ? sigma : 1.0);
    return testing::imageOn<ScalarImage>(grid, [&](const PhysicalPoint& y) { return float(texture(source(y)) + (sigma > 0 ? noise(rng) : 0.0)); });
  };
  const LabelImage::Pointer scanLabels =
    testing::imageOn<LabelImage>(grid, [&](const PhysicalPoint& y) { return LabelPixel(distance(source(y), {0, 0, 0}) > 26 ? 0 : 2); });
  auto identity = itk::Euler3DTransform<double>::New();
  const DisplacementPrediction none;
  BlockMatchingParameters parameters;
  parameters.blockHalfSizeMm = 4;
  parameters.blockSpacingMm = 4;
  parameters.selectedShare = 1.0;
  parameters.minimumSimilarity = 0.2;
  auto medianError = [&](const ScalarImage& scan, double smoothingMm, std::size_t& matched) {
    parameters.smoothingMm = smoothingMm;
    const BlockMatchingResult r = matchBlocks(*preop, *labels, scan, *scanLabels, *identity, none, parameters);
    matched = r.matches.size();
    const std::vector<double> errors = sortedErrors(r, shift);
    return errors.empty() ? 99.0 : errors[errors.size() / 2];
  };
  const ScalarImage::Pointer noisy = scanWithNoise(60), clean = scanWithNoise(0);
  std::size_t rawMatched = 0, smoothMatched = 0, cleanMatched = 0, cleanSmoothMatched = 0;
  const double raw = medianError(*noisy, 0, rawMatched), smoothed = medianError(*noisy, 0.7, smoothMatched);
  const double cleanRaw = medianError(*clean, 0, cleanMatched), cleanSmoothed = medianError(*clean, 0.7, cleanSmoothMatched);
  std::cout << "heavy noise: error median " << raw << " mm (" << rawMatched << " matched), both images smoothed (0.7 mm) " << smoothed << " mm ("
            << smoothMatched << "); without noise " << cleanRaw << " / " << cleanSmoothed << " mm\n";
  BS_CHECK_MSG(rawMatched > 100 && smoothMatched >= rawMatched * 9 / 10, rawMatched << ", " << smoothMatched);
  BS_CHECK_MSG(smoothed < 0.75 * raw, smoothed << " vs " << raw);
  BS_CHECK_MSG(cleanRaw < 0.3 && cleanSmoothed <= cleanRaw + 0.02, cleanSmoothed << " vs " << cleanRaw);
  BS_CHECK_MSG(cleanSmoothMatched >= cleanMatched * 95 / 100, cleanSmoothMatched << " vs " << cleanMatched);
  // One image on both sides (nothing moved, the same noise in both): smoothed alike they correlate
  // fully where they lie (were one of them smoothed alone, its noise would not match the other's).
  const ScalarImage::Pointer still = testing::imageOn<ScalarImage>(grid, [&, rng = std::mt19937_64(29)](const PhysicalPoint& p) mutable {
    return float(texture(p) + std::normal_distribution<double>(0.0, 60.0)(rng));
  });
  parameters.smoothingMm = 0.7;
  const BlockMatchingResult same = matchBlocks(*still, *labels, *still, *labels, *identity, none, parameters);
  std::vector<double> similarities;
  for (const BlockMatch& m : same.matches) similarities.push_back(m.similarity);
  std::sort(similarities.begin(), similarities.end());
  const std::vector<double> stillErrors = sortedErrors(same, {0, 0, 0});
  const double lowest = similarities.empty() ? -1 : similarities.front();
  const double stillMedian = stillErrors.empty() ? 99 : stillErrors[stillErrors.size() / 2];
  std::cout << "the same noisy image on both sides, smoothed: " << same.matches.size() << " matched, the lowest correlation " << lowest
            << ", error median " << stillMedian << " mm\n";
  BS_CHECK_MSG(same.matches.size() > 100, same.matches.size());
  BS_CHECK_MSG(lowest > 0.99, lowest);
  BS_CHECK_MSG(stillMedian < 0.05, stillMedian);
  parameters.smoothingMm = -1;
  BS_CHECK_THROWS(matchBlocks(*preop, *labels, *noisy, *scanLabels, *identity, none, parameters), std::invalid_argument, "smoothing");
}
} // namespace

int BlockMatchingTest(int, char*[])
{
  return testing::runTest("BlockMatchingTest", [] {
    const std::array<double, 3> shift{2.4, -1.7, 3.1};
    const std::array<double, 3> cavity{-15, 10, 5}; // in the scan's preoperative frame, after the shift
    const ImageGeometry preopGrid = testing::grid({{64, 64, 64}}, {1.5, 1.5, 1.5}, testing::point(-48, -48, -48));
    const ScalarImage::Pointer preop = testing::imageOn<ScalarImage>(preopGrid, [](const PhysicalPoint& p) { return float(texture(p)); });
    const std::array<double, 3> tumour{15, -12, 0};
    LabelImage::Pointer preopLabels = testing::imageOn<LabelImage>(preopGrid, [&](const PhysicalPoint& p) {
      const double r = distance(p, {0, 0, 0});
      return LabelPixel(r > 38 ? 0 : distance(p, tumour) < 7 ? 4 : 2);
    });
    // The scan: its own grid and pose, the tissue moved by `shift`, contrast inverted, noise.
    auto rigid = itk::Euler3DTransform<double>::New(); // intraoperative -> preoperative
    rigid->SetRotation(0.05, -0.03, 0.08);
    itk::Euler3DTransform<double>::OutputVectorType translation;
    translation[0] = 1.5;
    translation[1] = -2.0;
    translation[2] = 0.5;
    rigid->SetTranslation(translation);
    const ImageGeometry intraopGrid = testing::grid({{70, 70, 50}}, {1.4, 1.4, 2.0}, testing::point(-49, -49, -50));
    std::mt19937_64 rng(5);
    std::normal_distribution<double> noise(0.0, 2.0);
    auto moved = [&](const PhysicalPoint& y) {
      const PhysicalPoint p = rigid->TransformPoint(y);
      return testing::point(p[0] - shift[0], p[1] - shift[1], p[2] - shift[2]); // the preoperative tissue seen at y
    };
    const ScalarImage::Pointer intraop = testing::imageOn<ScalarImage>(intraopGrid, [&](const PhysicalPoint& y) {
      return float(400 - 2.5 * texture(moved(y)) + noise(rng));
    });
    const LabelImage::Pointer intraopLabels = testing::imageOn<LabelImage>(intraopGrid, [&](const PhysicalPoint& y) {
      const PhysicalPoint x = moved(y);
      return LabelPixel(distance(x, {0, 0, 0}) > 38 || distance(rigid->TransformPoint(y), cavity) < 9 ? 0 : 2);
    });

    BlockMatchingParameters parameters;
    parameters.blockHalfSizeMm = 4.5;
    parameters.blockSpacingMm = 6;
    parameters.selectedShare = 1.0;
    parameters.excludedLabels = {4};
    const DisplacementPrediction none;
    const BlockMatchingResult result = matchBlocks(*preop, *preopLabels, *intraop, *intraopLabels, *rigid, none, parameters);
    const std::vector<double> errors = sortedErrors(result, shift);
    std::size_t nearTumour = 0, inCavity = 0;
    for (const BlockMatch& m : result.matches) {
      if (distance(m.centre, tumour) < 7 + parameters.blockHalfSizeMm) ++nearTumour;
      PhysicalPoint target = m.centre;
      for (int a = 0; a < 3; ++a) target[a] += m.displacement[std::size_t(a)];
      if (distance(target, cavity) < 6) ++inCavity; // a block may reach 30 % into it (minimumBrainShare)
    }
    const double median = errors.empty() ? 99 : errors[errors.size() / 2];
    const double p95 = errors.empty() ? 99 : errors[std::size_t(0.95 * double(errors.size() - 1))];
    std::cout << result.candidates << " candidates, " << result.selected << " selected, " << result.matches.size() << " matched ("
              << result.lowSimilarity << " low similarity, " << result.outsideBrain << " outside the brain, " << result.atSearchEdge
              << " at the search edge); error median " << median << " mm, p95 " << p95 << " mm; remap eta^2 "
              << result.remapCorrelationRatio << "; near the tumour " << nearTumour << ", into the cavity " << inCavity << '\n';
    BS_CHECK_MSG(result.selected >= 100, result.selected);
    BS_CHECK_MSG(result.matches.size() >= result.selected * 8 / 10, result.matches.size());
    BS_CHECK_MSG(median < 0.35, median);
    BS_CHECK_MSG(p95 < 0.8, p95);
    BS_CHECK_MSG(result.outsideBrain > 0, result.outsideBrain);
    BS_CHECK_MSG(inCavity == 0, inCavity);
    BS_CHECK_MSG(nearTumour == 0, nearTumour);
    for (const BlockMatch& m : result.matches) BS_CHECK_MSG(m.similarity > 0.5, m.similarity); // positive through the inversion

    // A ball of the scan at one grey level: its windows are flat, no block matches inside it.
    const std::array<double, 3> flatCentre{-5, -20, 10}; // in the scan's preoperative frame
    const ScalarImage::Pointer flat = testing::imageOn<ScalarImage>(intraopGrid, [&](const PhysicalPoint& y) {
      return distance(rigid->TransformPoint(y), flatCentre) < 14 ? 250.0f : intraop->GetPixel(intraop->TransformPhysicalPointToIndex(y));
    });
    const BlockMatchingResult withFlat = matchBlocks(*preop, *preopLabels, *flat, *intraopLabels, *rigid, none, parameters);
    std::size_t inFlat = 0;
    double highest = -2;
    for (const BlockMatch& m : withFlat.matches) {
      PhysicalPoint target = m.centre;
      for (int a = 0; a < 3; ++a) target[a] += m.displacement[std::size_t(a)];
      if (distance(target, flatCentre) < 5) ++inFlat;
      highest = std::max(highest, m.similarity);
    }
    for (const BlockMatch& m : result.matches) highest = std::max(highest, m.similarity);
    std::cout << "a flat ball of 14 mm: " << withFlat.matches.size() << " matched (" << withFlat.lowSimilarity
              << " low similarity), " << inFlat << " inside it; the highest correlation " << highest << '\n';
    BS_CHECK_MSG(inFlat == 0, inFlat);
    BS_CHECK_MSG(withFlat.lowSimilarity > result.lowSimilarity, withFlat.lowSimilarity << " vs " << result.lowSimilarity);
    BS_CHECK_MSG(highest <= 1 + 1e-9, highest);

    // A prediction 4 mm off: found again within the search window.
    const DisplacementPrediction off = [&](const PhysicalPoint&) {
      return PredictedDisplacement{{shift[0] + 2.5, shift[1] - 2.0, shift[2] + 2.4}, std::nullopt};
    };
    const BlockMatchingResult corrected = matchBlocks(*preop, *preopLabels, *intraop, *intraopLabels, *rigid, off, parameters);
    const std::vector<double> correctedErrors = sortedErrors(corrected, shift);
    const double correctedMedian = correctedErrors.empty() ? 99 : correctedErrors[correctedErrors.size() / 2];
    std::cout << "prediction 4 mm off: " << corrected.matches.size() << " matched, error median " << correctedMedian << " mm\n";
    BS_CHECK_MSG(corrected.matches.size() >= result.matches.size() * 9 / 10, corrected.matches.size());
    BS_CHECK_MSG(correctedMedian < 0.35, correctedMedian);

    // The remap is learned where the scan's brain overlaps the preoperative one: here the whole
    // texture moved by 4 mm (wavelengths of 6 to 17 mm), so it sees little of the relation; the
    // same scan without the shift shows it whole.
    const ScalarImage::Pointer unmoved = testing::imageOn<ScalarImage>(intraopGrid, [&](const PhysicalPoint& y) {
      return float(400 - 2.5 * texture(rigid->TransformPoint(y)) + noise(rng));
    });
    const BlockMatchingResult still = matchBlocks(*preop, *preopLabels, *unmoved, *intraopLabels, *rigid, none, parameters);
    std::cout << "without the shift: remap eta^2 " << still.remapCorrelationRatio << " (with it " << result.remapCorrelationRatio << ")\n";
    BS_CHECK_MSG(still.remapCorrelationRatio > 0.8, still.remapCorrelationRatio);
    BS_CHECK_MSG(result.remapCorrelationRatio < 0.5, result.remapCorrelationRatio);

    checkMatchesHeldAgainstNewClassification(result, *preop, *intraopLabels, *rigid, parameters, [&](const PhysicalPoint& y) {
      const PhysicalPoint inPreop = rigid->TransformPoint(y);
      return distance(moved(y), {0, 0, 0}) > 38 || distance(inPreop, cavity) < 9 || distance(inPreop, {12, 14, -8}) < 9;
    });

    checkSelectionSpreadOverTheBrain();
    checkDeformedWindowsUnderShear();
    checkSmoothingAgainstNoise();

    parameters.searchRadiusMm = 0;
    BS_CHECK_THROWS(matchBlocks(*preop, *preopLabels, *intraop, *intraopLabels, *rigid, none, parameters), std::invalid_argument, "search radius");
    parameters.searchRadiusMm = 6;
    parameters.selectedShare = 1.5;
    BS_CHECK_THROWS(matchBlocks(*preop, *preopLabels, *intraop, *intraopLabels, *rigid, none, parameters), std::invalid_argument, "selected share");
    parameters.selectedShare = 1.0;
    parameters.selectionCellMm = -1;
    BS_CHECK_THROWS(matchBlocks(*preop, *preopLabels, *intraop, *intraopLabels, *rigid, none, parameters), std::invalid_argument, "selection's cell");
    parameters.selectionCellMm = 1e-7; // a cube index past int
    BS_CHECK_THROWS(matchBlocks(*preop, *preopLabels, *intraop, *intraopLabels, *rigid, none, parameters), std::invalid_argument, "selection's cell");
  });
}
