#include "FileNames.h"

#include <algorithm>
#include <cctype>

namespace brainshift {

std::string lowerCaseFileName(const std::filesystem::path& path)
{
  std::string name = path.filename().string();
  std::transform(name.begin(), name.end(), name.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return name;
}

bool hasExtension(const std::filesystem::path& path, std::initializer_list<const char*> extensions)
{
  const std::string name = lowerCaseFileName(path);
  for (const std::string suffix : extensions) {
    if (name.size() >= suffix.size() && name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0) {
      return true;
    }
  }
  return false;
}

} // namespace brainshift
