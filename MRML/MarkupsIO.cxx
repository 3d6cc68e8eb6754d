#include "MarkupsIO.h"

#include "AtomicFile.h"
#include "BrainShiftErrors.h"

#include <nlohmann/json.hpp>

#include <cmath>

namespace brainshift {
namespace fs = std::filesystem;
using nlohmann::json;

std::vector<NamedPoint> readMarkupsJson(const fs::path& path)
{
  json document;
  try {
    document = json::parse(readTextFile(path));
  } catch (const json::exception& e) {
    throw InputError(path.string() + ": not a valid JSON markups file: " + e.what());
  }
  if (!document.is_object() || !document.contains("markups") || !document["markups"].is_array() ||
      document["markups"].empty()) {
    throw InputError(path.string() + ": no 'markups' list in the file");
  }
  const json& markup = document["markups"][0];
  const std::string system = markup.value("coordinateSystem", "LPS");
  if (system != "LPS" && system != "RAS") {
    throw InputError(path.string() + ": unknown coordinateSystem '" + system + "' (LPS or RAS)");
  }
  const double flip = system == "RAS" ? -1.0 : 1.0;
  std::vector<NamedPoint> points;
  for (const json& point : markup.value("controlPoints", json::array())) {
    if (!point.contains("position") || !point["position"].is_array() || point["position"].size() != 3) {
      throw InputError(path.string() + ": control point '" + point.value("label", "") + "' has no 3D position");
    }
    NamedPoint named;
    named.name = point.value("label", "");
    for (int i = 0; i < 3; ++i) {
      if (!point["position"][i].is_number()) {
        throw InputError(path.string() + ": control point '" + named.name + "' has a non-numeric coordinate");
      }
      named.position[i] = point["position"][i].get<double>() * (i < 2 ? flip : 1.0);
      if (!std::isfinite(named.position[i])) {
        throw InputError(path.string() + ": control point '" + named.name + "' has a non-finite coordinate");
      }
    }
    points.push_back(named);
  }
  return points;
}

void writeMarkupsJson(const std::vector<NamedPoint>& points, const fs::path& path, bool locked)
{
  json controlPoints = json::array();
  int id = 1;
  for (const NamedPoint& point : points) {
    controlPoints.push_back({{"id", std::to_string(id++)},
                             {"label", point.name},
                             {"description", ""},
                             {"associatedNodeID", ""},
                             {"position", {point.position[0], point.position[1], point.position[2]}},
                             {"orientation", {-1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0}},
                             {"selected", true},
                             {"locked", locked},
                             {"visibility", true},
                             {"positionStatus", "defined"}});
  }
  json document = {
    {"@schema", "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/Schema/markups-schema-v1.0.3.json#"},
    {"markups",
     {{{"type", "Fiducial"},
       {"coordinateSystem", "LPS"},
       {"coordinateUnits", "mm"},
       {"locked", locked},
       {"fixedNumberOfControlPoints", false},
       {"labelFormat", "%N-%d"},
       {"lastUsedControlPointNumber", static_cast<int>(points.size())},
       {"controlPoints", controlPoints},
       {"measurements", json::array()}}}}};
  writeTextFileAtomically(path, document.dump(4) + "\n");
}

} // namespace brainshift
