#pragma once
// What the refine stage (the classification that follows the brain) computes besides the
// classification itself: where the last solve moved the tissue, and the first classification kept
// everywhere else (an ambiguous boundary left to the warped prior alone follows the last pass's
// own error from pass to pass: 40-50 ml flipped at the skull base).
#include "DistanceMaps.h"
#include "ImageTypes.h"
#include "TransformIO.h"

#include <cstddef>

namespace brainshift {

/// On the field's grid: within `reachMm` of the voxels where the non-rigid part of the mapping
/// y -> x = y + d(y) (the rigid transform taken out) exceeds `movedMm`.
MaskImage::Pointer regionMovedBySolve(const DisplacementFieldImage& field, const SpatialTransform& rigidIntraopToPreop,
                                      double movedMm, double reachMm);

/// `labels` takes `anchor`'s value outside `region` (all three on one grid; std::invalid_argument
/// otherwise). Returns how many voxels inside the region differ from the anchor.
std::size_t keepAnchorOutside(LabelImage& labels, const LabelImage& anchor, const MaskImage& region);

} // namespace brainshift
