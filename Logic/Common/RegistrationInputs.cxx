#include "RegistrationInputs.h"

#include "VolumeIO.h"

#include <algorithm>
#include <set>
#include <sstream>

namespace brainshift {
namespace fs = std::filesystem;

OverlayInput parseOverlayArgument(const std::string& text)
{
  const auto equals = text.find('=');
  if (equals == std::string::npos || equals == 0 || equals + 1 == text.size()) {
    throw InputError("--overlay '" + text + "': expected NAME=FILE");
  }
  OverlayInput overlay{text.substr(0, equals), text.substr(equals + 1)};
  for (unsigned char c : overlay.name) {
    if (!std::isalnum(c) && c != '-' && c != '_') {
      throw InputError("--overlay '" + text + "': the name may hold letters, digits, '-' and '_' only");
    }
  }
  // warped_<NAME>.nii.gz must not replace a built-in output (warped_preop_image.nii.gz, ...).
  for (const char* builtIn : {"preop_image", "preop_labels", "intraop_image", "intraop_labels"}) {
    if (overlay.name == builtIn) {
      throw InputError("--overlay '" + text + "': the name " + overlay.name + " is taken by a built-in output (warped_" +
                       overlay.name + ".nii.gz); choose another name");
    }
  }
  return overlay;
}

namespace {
void requireNotConstant(const ScalarImage* image, const fs::path& path)
{
  const float* v = image->GetBufferPointer();
  const std::size_t n = image->GetLargestPossibleRegion().GetNumberOfPixels();
  const auto [lo, hi] = std::minmax_element(v, v + n);
  if (*lo == *hi) {
    std::ostringstream message;
    message << path.string() << ": a constant image (every voxel is " << *lo << "); nothing to register";
    throw InputError(message.str());
  }
}
} // namespace

ScalarImage::Pointer readIntensityImage(const fs::path& path, Warnings* warnings)
{
  ScalarImage::Pointer image = readScalarVolume(path, warnings);
  requireNotConstant(image, path);
  return image;
}

RegistrationInputs loadRegistrationInputs(const RegistrationInputPaths& paths)
{
  RegistrationInputs inputs;
  inputs.preopImage = readIntensityImage(paths.preopImage, &inputs.warnings);
  inputs.preopLabels = readLabelVolume(paths.preopLabels, &inputs.warnings);
  const ImageGeometry imageGrid = ImageGeometry::of(inputs.preopImage.GetPointer());
  const ImageGeometry labelGrid = ImageGeometry::of(inputs.preopLabels.GetPointer());
  if (!labelGrid.sameGridAs(imageGrid)) {
    throw InputError(paths.preopLabels.string() + ": the labels are on another grid (" + labelGrid.describe() +
                     ") than the preoperative image " + paths.preopImage.string() + " (" + imageGrid.describe() + ")");
  }
  std::set<LabelPixel> present;
  const LabelPixel* l = inputs.preopLabels->GetBufferPointer();
  for (std::size_t i = 0, n = labelGrid.numberOfVoxels(); i < n; ++i) present.insert(l[i]);
  if (!present.count(2) && !present.count(3) && !present.count(4)) {
    throw InputError(paths.preopLabels.string() +
                     ": no brain tissue in the label map (labels 2 parenchyma, 3 ventricles, 4 tumour are all absent)");
  }
  if (!present.count(2)) {
    warn(&inputs.warnings, paths.preopLabels.string() + ": no brain parenchyma (label 2) in the label map");
  }
  if (!paths.intraopImage.empty()) inputs.intraopImage = readIntensityImage(paths.intraopImage, &inputs.warnings);
  std::set<std::string> names;
  for (const OverlayInput& overlay : paths.overlays) {
    if (!names.insert(overlay.name).second) {
      throw InputError("--overlay " + overlay.name + ": the name is given twice");
    }
    inputs.overlays.push_back({overlay.name, readScalarVolume(overlay.file, &inputs.warnings)});
  }
  return inputs;
}

} // namespace brainshift
