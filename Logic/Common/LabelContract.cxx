#include "LabelContract.h"

#include "BrainShiftErrors.h"

#include <map>
#include <set>
#include <string>

namespace brainshift {

void requireKnownLabels(const LabelImage& labels, const std::filesystem::path& path, const Configuration& configuration)
{
  std::set<int> known{0, 1, 2, 3, 4};
  for (const auto& entry : configuration.materials) known.insert(entry.first);
  known.insert(configuration.meshLabels.begin(), configuration.meshLabels.end());
  std::map<int, std::size_t> unknown;
  const LabelPixel* voxel = labels.GetBufferPointer();
  for (std::size_t i = 0, n = labels.GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) {
    if (!known.count(int(voxel[i]))) ++unknown[int(voxel[i])];
  }
  if (unknown.empty()) return;
  std::string values;
  for (const auto& [value, count] : unknown) {
    if (values.size() > 120) {
      values += ", ...";
      break;
    }
    values += (values.empty() ? "" : ", ") + std::to_string(value) + " (" + std::to_string(count) + " voxels)";
  }
  std::string knownList;
  for (int label : known) knownList += (knownList.empty() ? "" : ", ") + std::to_string(label);
  throw InputError(path.string() + ": label values " + values + " are not labels of this case (known: " + knownList +
                   "; 0 background, 1 head, 2 parenchyma, 3 ventricles, 4 tumour, and the configuration's materials "
                   "and mesh labels)");
}

} // namespace brainshift
