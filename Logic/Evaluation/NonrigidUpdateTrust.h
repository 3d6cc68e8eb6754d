#pragma once
// Whether the non-rigid part of an intraoperative update can be shown: the preoperative image
// warped by the whole update must explain the intraoperative scan at least as well as the same
// image under the rigid transform alone, near the brain's boundary (where a wrong segmentation
// drags the surface) and inside. The intraoperative scan may have another contrast (T2, FLAIR,
// low field), so the similarity is the correlation ratio eta^2 = 1 - E[Var(I | W)] / Var(I) of the
// intraoperative intensity I given the warped preoperative intensity W (in bins): any functional
// relation between the two contrasts scores high, an inverted one as well. Where the relation is a
// function only the other way (a T1's dark CSF, bone and air are bright fluid and dark bone and air
// in a T2), eta^2 of W given I; each region keeps the direction in which the update gains more. It
// judges the update with the image alone, not with the classification it was built from.
#include "ImageTypes.h"

#include <optional>
#include <string>
#include <vector>

namespace brainshift {

enum class UpdateTrust { Trusted, Doubtful, Rejected };
/// "trusted", "doubtful", "rejected".
std::string trustName(UpdateTrust trust);

/// eta^2 of the intraoperative image given each warp, on the same voxels and the same bins.
struct RegionSimilarity {
  std::size_t voxels = 0;
  double nonrigid = 0, rigid = 0;
  /// eta^2 of the warped preoperative image given the intraoperative one (the update gained more
  /// that way: bothDirections), not of the intraoperative given the warped preoperative.
  bool preoperativeGivenIntraoperative = false;
  double gain() const { return nonrigid - rigid; }
};

/// All images on the intraoperative grid. Optional pointers may be null.
struct NonrigidUpdateTrustInputs {
  const ScalarImage* intraop = nullptr;
  const ScalarImage* warpedByUpdate = nullptr; ///< the preoperative image under the whole update
  const ScalarImage* warpedByRigid = nullptr;  ///< the same under the rigid transform alone
  /// The brain (labels 2, 3, 4) of these label maps places the regions: the band is within
  /// `bandHalfWidthMm` of a voxel on either side of any of their brain boundaries; the interior is
  /// inside the first given of the classification and the rigidly warped labels, beyond the band.
  /// At least one is needed.
  const LabelImage* intraopLabels = nullptr;
  const LabelImage* labelsWarpedByUpdate = nullptr;
  const LabelImage* labelsWarpedByRigid = nullptr;
  /// Both mappings as fields (x = y + d(y)): where they differ by `movedMm` or more, and the
  /// classification or the labels warped by the update show brain, is where the update moved the
  /// brain (the "moved" region, the sharpest test; not the gap nor the skull above a sunken brain,
  /// where the field only carries the brain's boundary across).
  const DisplacementFieldImage* updateField = nullptr;
  const DisplacementFieldImage* rigidField = nullptr;
  // What the earlier stages reported (report.json), when known.
  std::optional<double> surfaceMeanResidualMm;
  std::optional<std::size_t> surfaceNodes, unmatchedSurfaceNodes; ///< nodes freed because no boundary matched
  /// The voxels inside the deformed mesh (the brain), and those of them where the field folds.
  std::optional<std::size_t> foldedVoxels, meshVoxels;
};

/// Thresholds chosen on the built-in cases (Testing/Benchmarks/trust/, README).
struct NonrigidUpdateTrustParameters {
  double bandHalfWidthMm = 5.0;
  double movedMm = 1.0;
  unsigned bins = 32;
  /// Score each region both ways (I given W and W given I) and keep the way the update gains more:
  /// a T1's one dark look (CSF, bone, air) is two in a T2 (bright fluid, dark bone and air), a
  /// relation that is a function only from the T2 to the T1. False: I given W alone.
  bool bothDirections = true;
  std::size_t minimumVoxels = 300; ///< a region with fewer voxels is not scored
  /// The gain of eta^2 (update minus rigid; where the update moves the brain, else near the
  /// boundary) below which the update is rejected, and below which it is doubtful (not clearly better).
  double rejectGainBelow = -0.005;
  double doubtGainBelow = 0.01;
  /// Mixed evidence: where the update moves the brain it matches a little worse (a gain between
  /// `mixedLossDownTo` and `rejectGainBelow`) while inside the brain, beyond the boundary band (where
  /// the image's own block matches carry the update), it matches clearly better (a gain of at least
  /// `mixedInteriorGainFrom`): doubtful, shown with its reason, instead of rejected. A larger loss,
  /// or no clear gain inside, is still rejected.
  double mixedLossDownTo = -0.05;
  double mixedInteriorGainFrom = 0.005;
  /// Share of the surface nodes freed because no boundary matched them.
  double rejectUnmatchedShare = 0.30, doubtUnmatchedShare = 0.15;
  double doubtResidualMm = 1.5;
  /// Share of the mesh's voxels where the deformation folds (a few voxels fold in good updates too).
  double rejectFoldedShare = 0.02, doubtFoldedShare = 0.005;
};

struct NonrigidUpdateTrustAssessment {
  UpdateTrust trust = UpdateTrust::Trusted;
  RegionSimilarity band, interior, moved;
  double unmatchedShare = 0, foldedShare = 0;
  std::vector<std::string> reasons; ///< why it is doubtful or rejected; empty when trusted
};

/// std::invalid_argument when an image is missing or not on the intraoperative grid, or no label
/// map is given.
NonrigidUpdateTrustAssessment assessNonrigidUpdate(const NonrigidUpdateTrustInputs& inputs,
                                                   const NonrigidUpdateTrustParameters& parameters = {});

/// eta^2 of `values` given `predictor` (both per voxel, same length) with `bins` equal bins of the
/// predictor between `low` and `high` (values beyond go to the end bins); 0 when `values` is constant.
double correlationRatio(const std::vector<float>& values, const std::vector<float>& predictor, unsigned bins, double low,
                        double high);

} // namespace brainshift
