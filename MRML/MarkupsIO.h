#pragma once
// 3D Slicer markups files (.mrk.json, schema v1.0): a fiducial list of named control points, LPS.
#include "BrainShiftErrors.h"
#include "ImageTypes.h"

#include <filesystem>
#include <string>
#include <vector>

namespace brainshift {

struct NamedPoint {
  std::string name;
  PhysicalPoint position;
};

/// Reads the control points of the first markup. Positions in a file that says RAS are converted.
std::vector<NamedPoint> readMarkupsJson(const std::filesystem::path& path);

/// Writes one fiducial markup in LPS, atomically. `locked` is written for the list and for each
/// point (Slicer applies the file's lock over the scene's when it loads the file).
void writeMarkupsJson(const std::vector<NamedPoint>& points, const std::filesystem::path& path, bool locked = false);

} // namespace brainshift
