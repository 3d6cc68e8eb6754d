#pragma once
// The values of the scene's layers at a point (LPS mm): what the slice views read out under the
// cursor. Intensities are interpolated linearly, labels taken at the nearest voxel.
#include "ImageTypes.h"

#include <QString>

#include <optional>
#include <vector>

namespace brainshift {

/// The intensity at `p`, or nothing outside the image.
std::optional<double> intensityAt(const ScalarImage& image, const PhysicalPoint& p);
/// The label at `p`, or nothing outside the image.
std::optional<LabelPixel> labelAt(const LabelImage& image, const PhysicalPoint& p);

struct LayerValue {
  QString layer;                ///< the node's name
  std::optional<double> value;  ///< nothing: outside the layer's volume
};

/// "LPS (12.0, -30.5, 40.0) mm | intraop image 431.2 | labels 2 | fMRI outside".
QString formatReadout(const PhysicalPoint& p, const std::vector<LayerValue>& values);

} // namespace brainshift
