#pragma once
// Intensity statistics shared by the stages: Otsu thresholds and the foreground of an image.
#include <cstddef>
#include <vector>

namespace brainshift {

/// Otsu's thresholds splitting the values (where `mask` is non-zero, if given) into `classes`
/// classes (2 or 3), from a 256-bin histogram over [lo, hi].
std::vector<double> otsuThresholds(const float* values, std::size_t count, int classes, double lo, double hi,
                                   const unsigned char* mask = nullptr);

} // namespace brainshift
