#pragma once
// Where the surgeon looks first in an update's scene: the strongest activation of the first warped
// statistics overlay (its largest |value|), else the centre of the warped tumour. The host's
// Intraoperative update module moves the views there when a scan's result comes in.
#include "Scene.h"

#include <array>
#include <optional>

namespace brainshift {

/// The name the update gives its confidence map in the scene (not an overlay to look at first).
inline constexpr const char* DisplacementUncertaintyNodeName = "displacement uncertainty (mm)";

/// LPS mm; none when the scene has neither a warped overlay with data nor a warped tumour
/// (label 4 of "warped preop labels"). Non-finite voxels are ignored.
std::optional<std::array<double, 3>> updateFocusPoint(const Scene& scene);

} // namespace brainshift
