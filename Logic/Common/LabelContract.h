#pragma once
// The labels a preoperative label map may hold (../shared/CONTRACT.md): 0 background, 1 head,
// 2 parenchyma, 3 ventricles, 4 tumour, and those the configuration adds (its materials and its
// mesh labels). Any other value (255 from an editor's "all", a stray class) would be meshed as
// nothing or as the wrong tissue without a word.
#include "Configuration.h"
#include "ImageTypes.h"

#include <filesystem>

namespace brainshift {

/// InputError naming `path`, the unknown values, how many voxels hold them and the known labels.
void requireKnownLabels(const LabelImage& labels, const std::filesystem::path& path, const Configuration& configuration);

} // namespace brainshift
