#pragma once
// Block matching inside the brain (after Clatz et al. 2005, "Robust nonrigid registration to
// capture brain shift from intraoperative MRI"): blocks of the preoperative image where it carries
// structure, each found again in the intraoperative image brought into the preoperative frame by
// the rigid transform, starting from where a prediction (the surface-driven solve) puts it.
//
// The intraoperative contrast need not be the preoperative one: the preoperative image is first
// remapped into the intraoperative intensities by the conditional mean of the intraoperative
// intensity given the preoperative one over the brain (a functional relation learned from this
// scan: monotonic for T1, inverted for T2, folded for FLAIR), and blocks are compared by normalised
// cross-correlation with the remapped image.
//
// Frames: the model frame is the preoperative physical space (LPS mm). A match says that the
// tissue at `centre` in the preoperative image lies at `centre + displacement` in the deformed
// configuration, the frame in which the finite element displacement u(X) is solved.
#include "ImageTypes.h"
#include "TransformIO.h"

#include <array>
#include <cstddef>
#include <functional>
#include <optional>
#include <vector>

namespace brainshift {

struct BlockMatchingParameters {
  double blockHalfSizeMm = 4.0;   ///< a block spans 2 h + 1 voxels of the matching grid per axis
  double blockSpacingMm = 5.0;    ///< candidate block centres on a lattice this far apart
  double selectedShare = 0.5;     ///< of the candidates, this share is matched (as selectionCellMm orders them)
  std::size_t maximumBlocks = 1500;
  /// The selection spread over the brain: the candidates fall into cubes this wide, and the blocks
  /// are taken in rounds, each cube's most structured remaining candidate in each round (within a
  /// round, the more structured first). 0: the most structured of the whole brain first, wherever
  /// they lie (a textureless region near the cortex then gets none).
  double selectionCellMm = 0;
  double searchRadiusMm = 6.0;    ///< around the predicted displacement, per axis
  double coarseStepMm = 2.0;      ///< the first pass of the search; then 1 voxel, then sub-voxel
  double minimumDepthMm = 4.0;    ///< block centres at least this deep inside the brain
  double minimumSimilarity = 0.5; ///< normalised cross-correlation at the peak below this: no match
  double minimumBrainShare = 0.7; ///< of the matched block's voxels classified brain in the scan
  double gridSpacingMm = 1.0;     ///< the matching grid: the preoperative grid, no finer than this
  /// Both images on the matching grid (the remapped preoperative one and the scan) smoothed by a
  /// Gaussian of this sigma (mm) before blocks are chosen and matched: the scan's noise then moves
  /// a correlation's peak less (0: not smoothed; else 0.1 to 5 mm).
  double smoothingMm = 0.0;
  /// The largest displacement the prediction gives (mm): the matching grid reaches this far beyond
  /// the brain, with the search and the block.
  double largestPredictedMm = 25.0;
  std::vector<int> brainLabels{2, 3, 4};
  /// Preoperative labels whose tissue is gone from the scan (the tumour when resected): blocks that
  /// hold any of them are not matched.
  std::vector<int> excludedLabels;
  /// Where the prediction shears or stretches the brain (its gradient's norm between
  /// kDeformedWindowMinimumGradient and kDeformedWindowMaximumGradient), a block is matched twice: in the window translated by the
  /// prediction, as everywhere, and in the window the prediction's local affine map deforms (its
  /// gradient at the block's centre), so that what remains to be found is nearly a translation;
  /// the higher correlation is kept. False: translated alone.
  bool deformedWindows = false;
};

/// The least norm (Frobenius, of the physical gradient) at which a block is also matched in its
/// deformed window (see BlockMatchingParameters::deformedWindows): below it the two windows differ
/// by less than a tenth of a millimetre per millimetre from the centre.
constexpr double kDeformedWindowMinimumGradient = 0.1;
/// The largest: a prediction that stretches or shears the tissue by more than its own size is not
/// a shape to match in (it is left to the translated window).
constexpr double kDeformedWindowMaximumGradient = 1.0;

struct BlockMatch {
  PhysicalPoint centre;                ///< preoperative frame (mm)
  std::array<double, 3> predicted{};   ///< the displacement the search started from (mm)
  std::array<double, 3> displacement{}; ///< the displacement found (mm)
  double similarity = 0;               ///< normalised cross-correlation at the peak
  double sharpness = 0;                ///< mean fall of the correlation one voxel off the peak
  /// The block's gradient structure tensor (of the remapped image), divided by its largest
  /// eigenvalue: 1 along the directions the block's structure pins down, 0 along those it does
  /// not (an edge leaves its tangent free). xx, xy, xz, yy, yz, zz.
  std::array<double, 6> structure{};
};

struct BlockMatchingResult {
  std::vector<BlockMatch> matches;
  std::size_t candidates = 0;        ///< lattice centres deep enough in the brain
  std::size_t selected = 0;          ///< the share of the candidates matched
  /// The selection spread over cubes (selectionCellMm > 0): the cubes holding candidates, and those
  /// given at least one block (all of them when there are more blocks than cubes). 0 by structure alone.
  std::size_t selectionCells = 0, selectionCellsWithBlock = 0;
  std::size_t lowSimilarity = 0;     ///< dropped: the peak's correlation below the minimum
  std::size_t outsideBrain = 0;      ///< dropped: the matched block not brain in the scan
  std::size_t atSearchEdge = 0;      ///< dropped: the peak on the edge of the search window
  /// Blocks matched in their deformed window too (deformedWindows), and those whose match came from it.
  std::size_t deformedWindows = 0, deformedWindowsTaken = 0;
  double remapSeconds = 0, selectionSeconds = 0, matchingSeconds = 0;
  double remapCorrelationRatio = 0;  ///< eta^2 of the intraoperative given the preoperative intensity
};

/// What a prediction gives at a preoperative point: the displacement (mm, model frame) and, where it
/// knows it, its gradient there (gradient[a][b] = d displacement_a / d x_b).
struct PredictedDisplacement {
  std::array<double, 3> displacement{};
  std::optional<std::array<std::array<double, 3>, 3>> gradient;
};
/// The prediction at a preoperative point; nullopt where it gives none (outside the model: no
/// displacement predicted).
using DisplacementPrediction = std::function<std::optional<PredictedDisplacement>(const PhysicalPoint&)>;

/// Matches blocks of `preopImage` inside the brain of `preopLabels` in `intraopImage`, whose
/// classification `intraopLabels` (on its grid) says where the brain is in the scan.
/// `rigidIntraopToPreop` maps intraoperative to preoperative points. `prediction` may be empty (no
/// displacement predicted). std::invalid_argument for absurd parameters; a brain too small for a
/// block gives no matches, not an error.
BlockMatchingResult matchBlocks(const ScalarImage& preopImage, const LabelImage& preopLabels, const ScalarImage& intraopImage,
                                const LabelImage& intraopLabels, const SpatialTransform& rigidIntraopToPreop,
                                const DisplacementPrediction& prediction, const BlockMatchingParameters& parameters);

/// The matches of an earlier matching of the same scan (the same images and rigid transform) held
/// against a new classification of it, `intraopLabels` (on the scan's grid): those whose matched
/// block is still brain (`minimumBrainShare` of its voxels), the others counted outside the brain.
/// A refine pass's solve keeps the image's correspondences without matching again (they do not
/// depend on the classification but for this check). `preopImage` gives the blocks' axes and the
/// matching grid's spacing, as matchBlocks set them. The earlier counts are kept; its seconds are
/// this check's (as the selection's).
BlockMatchingResult matchesStillInBrain(const BlockMatchingResult& earlier, const ScalarImage& preopImage, const LabelImage& intraopLabels,
                                        const SpatialTransform& rigidIntraopToPreop, const BlockMatchingParameters& parameters);

} // namespace brainshift
