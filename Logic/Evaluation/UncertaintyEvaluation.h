#pragma once
// Whether the update's confidence map (displacement_uncertainty_mm.nii.gz) says where the update
// is wrong: against a known truth, over the voxels of the brain in the scan, the estimate's rank
// correlation with the true error of the mapping, and how often the voxels it calls reliable are.
#include "ImageTypes.h"
#include "TransformIO.h"

#include <set>

namespace brainshift {

struct UncertaintyValidation {
  std::size_t voxels = 0;              ///< brain voxels sampled
  double rankCorrelation = 0;          ///< Spearman, estimate against true error
  double meanTrueErrorMm = 0, meanEstimateMm = 0;
  double shareCalledBelow1Mm = 0;      ///< of the voxels, estimate < 1 mm
  double calledBelow1MmTrulyBelow1_5Mm = 0; ///< of those, true error < 1.5 mm
  double trueErrorWhereCalledAbove2MmMm = 0; ///< mean true error where the estimate says >= 2 mm
  ScalarImage::Pointer trueError;      ///< |x_update - x_truth| (mm) on the update's grid, every voxel
};

/// `update` maps each intraoperative voxel y to x = y + d(y) (the update's field), `truth` is the
/// true intraoperative-to-preoperative transform, `estimate` the confidence map on the same grid as
/// `update`, `truthLabels` the true intraoperative labels (their `brainLabels` are sampled, every
/// `stride` voxels per axis). std::invalid_argument when the grids differ.
UncertaintyValidation validateUncertainty(const DisplacementFieldImage& update, const SpatialTransform& truth, const ScalarImage& estimate,
                                          const LabelImage& truthLabels, const std::set<LabelPixel>& brainLabels = {2, 3, 4},
                                          unsigned stride = 2);

} // namespace brainshift
