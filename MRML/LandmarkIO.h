#pragma once
// Landmark pairs (../shared/CONTRACT.md): a CSV with the header
//   name,preop_x,preop_y,preop_z,intraop_x,intraop_y,intraop_z
// then one pair per line, LPS mm.
#include "BrainShiftErrors.h"
#include "ImageTypes.h"

#include <filesystem>
#include <string>
#include <vector>

namespace brainshift {

struct LandmarkPair {
  std::string name;
  PhysicalPoint preop;
  PhysicalPoint intraop;
};

/// InputError naming the file and line for a wrong header, a wrong field count, a value that is
/// not a finite number, a duplicate or empty name, or a file without pairs.
std::vector<LandmarkPair> readLandmarksCsv(const std::filesystem::path& path);

/// Writes atomically, full double precision. Names must not hold commas, quotes or line breaks.
void writeLandmarksCsv(const std::vector<LandmarkPair>& pairs, const std::filesystem::path& path);

} // namespace brainshift
