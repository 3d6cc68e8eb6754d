#pragma once
// The inputs of an intraoperative update (`brainshift register` and its stages), read and checked
// once: readable 3D images without NaNs, labels on the preoperative image's grid with brain
// tissue in them, intensity images that are not constant, overlays named NAME=FILE.
#include "BrainShiftErrors.h"
#include "ImageTypes.h"

#include <filesystem>
#include <string>
#include <vector>

namespace brainshift {

struct OverlayInput {
  std::string name; ///< letters, digits, '-' and '_': it becomes warped_<name>.nii.gz
  std::filesystem::path file;
};

/// Parses "NAME=FILE"; InputError naming the flag otherwise.
OverlayInput parseOverlayArgument(const std::string& text);

struct RegistrationInputPaths {
  std::filesystem::path preopImage, preopLabels, intraopImage;
  std::vector<OverlayInput> overlays;
};

struct LoadedOverlay {
  std::string name;
  ScalarImage::Pointer image;
};

struct RegistrationInputs {
  ScalarImage::Pointer preopImage;
  LabelImage::Pointer preopLabels;
  ScalarImage::Pointer intraopImage;
  std::vector<LoadedOverlay> overlays;
  Warnings warnings;
};

/// Reads an intensity image and checks it can be registered (not constant); InputError naming it.
ScalarImage::Pointer readIntensityImage(const std::filesystem::path& path, Warnings* warnings);

/// Reads and checks every input; the first problem is an InputError naming its file.
RegistrationInputs loadRegistrationInputs(const RegistrationInputPaths& paths);

} // namespace brainshift
