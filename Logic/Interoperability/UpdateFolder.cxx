#include "UpdateFolder.h"

#include "AtomicFile.h"
#include "BrainShiftErrors.h"

#include <nlohmann/json.hpp>

#include <algorithm>

namespace brainshift {
namespace fs = std::filesystem;

namespace {
std::optional<fs::path> fileIfPresent(const fs::path& folder, const char* name)
{
  std::error_code ec;
  const fs::path file = folder / name;
  if (fs::is_regular_file(file, ec)) return file;
  return std::nullopt;
}

bool hasSuffix(const std::string& text, const std::string& suffix)
{
  return text.size() > suffix.size() && text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

fs::path intraopImageOf(const fs::path& folder)
{
  const fs::path reportPath = folder / "report.json";
  nlohmann::json report;
  try {
    report = nlohmann::json::parse(readTextFile(reportPath));
  } catch (const nlohmann::json::exception& e) {
    throw InputError(reportPath.string() + ": not valid JSON (" + e.what() + ")");
  }
  const nlohmann::json* entry = nullptr;
  if (report.is_object() && report.contains("case_inputs") && report["case_inputs"].contains("intraop_image")) {
    entry = &report["case_inputs"]["intraop_image"];
  }
  if (!entry || !entry->contains("path") || !(*entry)["path"].is_string()) {
    throw InputError(reportPath.string() + ": records no case_inputs.intraop_image.path (not the report of a "
                                           "`brainshift register` or `demo`)");
  }
  fs::path image = (*entry)["path"].get<std::string>();
  if (image.is_relative()) image = folder / image;
  std::error_code ec;
  if (!fs::exists(image, ec)) {
    throw InputError(reportPath.string() + ": the intraoperative scan it names, " + image.string() + ", is gone");
  }
  return image;
}
} // namespace

UpdateFolderContents inspectUpdateFolder(const fs::path& folder)
{
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw InputError(folder.string() + ": --output-dir is not a folder");
  if (!fs::is_regular_file(folder / "report.json", ec)) {
    throw InputError(folder.string() + ": holds no report.json (not the output folder of `brainshift register`)");
  }
  UpdateFolderContents contents;
  contents.folder = folder;
  contents.intraopImage = intraopImageOf(folder);
  for (const fs::directory_entry& entry : fs::directory_iterator(folder)) {
    const std::string name = entry.path().filename().string();
    if (!entry.is_regular_file() || name.rfind("warped_", 0) != 0 || !hasSuffix(name, ".nii.gz")) continue;
    const std::string node = name.substr(0, name.size() - std::string(".nii.gz").size());
    contents.warpedVolumes.push_back({node, entry.path(), hasSuffix(node, "_labels")});
  }
  std::sort(contents.warpedVolumes.begin(), contents.warpedVolumes.end(),
            [](const UpdateVolume& a, const UpdateVolume& b) { return a.name < b.name; });
  if (contents.warpedVolumes.empty()) {
    throw InputError(folder.string() + ": holds no warped_*.nii.gz (the update has not run its warp stage)");
  }
  contents.rigidTransform = fileIfPresent(folder, "rigid_intraop_to_preop.tfm");
  contents.brainSurface = fileIfPresent(folder, "brain_surface.vtp");
  contents.displacementField = fileIfPresent(folder, "displacement_intraop_to_preop.nrrd");
  contents.uncertainty = fileIfPresent(folder, "displacement_uncertainty_mm.nii.gz");
  return contents;
}

} // namespace brainshift
