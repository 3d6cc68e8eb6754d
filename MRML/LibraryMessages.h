#pragma once
// A library's error text in one line: ITK's exception descriptions run over several lines
// ("ITK ERROR: Reader(0x...): Could not create IO object ...\n  Tried to create one of ...").
#include <string>

namespace brainshift {

/// The first non-empty line of `description`, without ITK's "ITK ERROR: Class(0x...): " prefix.
inline std::string oneLine(const std::string& description)
{
  std::string line;
  for (std::size_t start = 0; start < description.size() && line.empty();) {
    const std::size_t end = std::min(description.find('\n', start), description.size());
    line = description.substr(start, end - start);
    while (!line.empty() && (line.back() == ' ' || line.back() == '\r')) line.pop_back();
    start = end + 1;
  }
  if (line.rfind("ITK ERROR: ", 0) == 0) {
    const std::size_t object = line.find("): ");
    line = object == std::string::npos ? line.substr(11) : line.substr(object + 3);
  }
  while (!line.empty() && (line.back() == ':' || line.back() == ' ')) line.pop_back();
  return line;
}

} // namespace brainshift
