#pragma once
// Agreement of two label maps on one grid: Dice of a set of labels, and the mean (symmetric)
// distance between the boundaries of the two regions.
#include "ImageTypes.h"

#include <set>

namespace brainshift {

/// 2 |A and B| / (|A| + |B|) for the regions A, B where the labels are in `labels`; 1 when both are empty.
double diceCoefficient(const LabelImage& a, const LabelImage& b, const std::set<LabelPixel>& labels);

/// The mean over both boundaries of the distance (mm) from each boundary voxel to the other
/// region's boundary. std::invalid_argument when the grids differ.
double meanSurfaceDistanceMm(const LabelImage& a, const LabelImage& b, const std::set<LabelPixel>& labels);

} // namespace brainshift
