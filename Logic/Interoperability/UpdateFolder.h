#pragma once
// What an output folder of `register` (or `demo`) holds that can leave for the operating room's
// systems: the warped volumes, the intraoperative scan the update was computed on, the rigid
// transform, the deformed brain surface and the displacement. Read from the folder's files and its
// report.json (../shared/CONTRACT.md); nothing is written.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace brainshift {

/// A volume of the update: its node name (the file name without extension) and its file.
struct UpdateVolume {
  std::string name;            ///< e.g. "warped_preop_image", "warped_fmri"
  std::filesystem::path path;
  bool isLabelMap = false;     ///< label values (warped_preop_labels, intraop_labels)
};

struct UpdateFolderContents {
  std::filesystem::path folder;
  std::vector<UpdateVolume> warpedVolumes;            ///< warped_*.nii.gz, sorted by name
  std::filesystem::path intraopImage;                 ///< report.json case_inputs.intraop_image.path
  std::optional<std::filesystem::path> rigidTransform;     ///< rigid_intraop_to_preop.tfm
  std::optional<std::filesystem::path> brainSurface;       ///< brain_surface.vtp
  std::optional<std::filesystem::path> displacementField;  ///< displacement_intraop_to_preop.nrrd
  std::optional<std::filesystem::path> uncertainty;        ///< displacement_uncertainty_mm.nii.gz
};

/// Lists what `folder` holds. InputError naming the folder when it is not an update's output
/// folder (no report.json with case_inputs, no warped volume) or the intraoperative scan that its
/// report names is gone.
UpdateFolderContents inspectUpdateFolder(const std::filesystem::path& folder);

} // namespace brainshift
