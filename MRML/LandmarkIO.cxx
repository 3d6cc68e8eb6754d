#include "LandmarkIO.h"

#include "AtomicFile.h"
#include "BrainShiftErrors.h"

#include <cmath>
#include <iomanip>
#include <limits>
#include <set>
#include <sstream>

namespace brainshift {
namespace fs = std::filesystem;

namespace {
constexpr const char* Header = "name,preop_x,preop_y,preop_z,intraop_x,intraop_y,intraop_z";

std::string trim(const std::string& s)
{
  const auto begin = s.find_first_not_of(" \t\r");
  if (begin == std::string::npos) return "";
  const auto end = s.find_last_not_of(" \t\r");
  return s.substr(begin, end - begin + 1);
}

std::vector<std::string> splitFields(const std::string& line)
{
  std::vector<std::string> fields;
  std::string field;
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') {
        field += '"';
        ++i;
      } else if (c == '"') {
        quoted = false;
      } else {
        field += c;
      }
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      fields.push_back(trim(field));
      field.clear();
    } else {
      field += c;
    }
  }
  fields.push_back(trim(field));
  return fields;
}

double parseCoordinate(const std::string& text, const fs::path& path, std::size_t line, const char* column)
{
  std::size_t used = 0;
  double value = std::numeric_limits<double>::quiet_NaN();
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used == 0 || used != text.size() || !std::isfinite(value)) {
    throw InputError(path.string() + ":" + std::to_string(line) + ": " + column + " is '" + text +
                     "', not a finite number");
  }
  return value;
}
} // namespace

std::vector<LandmarkPair> readLandmarksCsv(const fs::path& path)
{
  std::istringstream in(readTextFile(path));
  std::string line;
  std::size_t lineNumber = 0;
  std::vector<LandmarkPair> pairs;
  std::set<std::string> names;
  bool headerSeen = false;
  static const char* columns[] = {"preop_x", "preop_y", "preop_z", "intraop_x", "intraop_y", "intraop_z"};
  while (std::getline(in, line)) {
    ++lineNumber;
    if (trim(line).empty()) continue;
    const std::vector<std::string> fields = splitFields(line);
    if (!headerSeen) {
      std::string header;
      for (std::size_t i = 0; i < fields.size(); ++i) header += (i ? "," : "") + fields[i];
      if (header != Header) {
        throw InputError(path.string() + ":" + std::to_string(lineNumber) + ": the header is '" + trim(line) +
                         "'; expected '" + Header + "'");
      }
      headerSeen = true;
      continue;
    }
    if (fields.size() != 7) {
      throw InputError(path.string() + ":" + std::to_string(lineNumber) + ": " + std::to_string(fields.size()) +
                       " fields; 7 expected (" + Header + ")");
    }
    LandmarkPair pair;
    pair.name = fields[0];
    if (pair.name.empty()) {
      throw InputError(path.string() + ":" + std::to_string(lineNumber) + ": the landmark has no name");
    }
    if (!names.insert(pair.name).second) {
      throw InputError(path.string() + ":" + std::to_string(lineNumber) + ": landmark '" + pair.name +
                       "' appears twice");
    }
    for (int i = 0; i < 3; ++i) {
      pair.preop[i] = parseCoordinate(fields[1 + i], path, lineNumber, columns[i]);
      pair.intraop[i] = parseCoordinate(fields[4 + i], path, lineNumber, columns[3 + i]);
    }
    pairs.push_back(pair);
  }
  if (!headerSeen) {
    throw InputError(path.string() + ": empty landmark file; expected the header '" + std::string(Header) + "'");
  }
  if (pairs.empty()) {
    throw InputError(path.string() + ": the landmark file holds no pairs");
  }
  return pairs;
}

void writeLandmarksCsv(const std::vector<LandmarkPair>& pairs, const fs::path& path)
{
  std::ostringstream out;
  out << Header << '\n' << std::setprecision(std::numeric_limits<double>::max_digits10);
  for (const LandmarkPair& pair : pairs) {
    if (pair.name.empty() || pair.name.find_first_of(",\"\n\r") != std::string::npos) {
      throw std::invalid_argument("landmark name '" + pair.name + "' cannot be written to CSV");
    }
    out << pair.name;
    for (int i = 0; i < 3; ++i) out << ',' << pair.preop[i];
    for (int i = 0; i < 3; ++i) out << ',' << pair.intraop[i];
    out << '\n';
  }
  writeTextFileAtomically(path, out.str());
}

} // namespace brainshift
