// Slicer markups (.mrk.json): a round trip of named points, conversion of a file in RAS, and
// positions written as JSON floating-point numbers (Slicer ignores integer positions).
#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "MarkupsIO.h"
#include "SyntheticData.h"

#include <fstream>
#include <vector>

namespace {
using namespace brainshift;
namespace fs = std::filesystem;
using brainshift::testing::point;

/// The numbers of every "position": [...] array in a JSON text, as written.
std::vector<std::string> positionNumbers(const std::string& json)
{
  std::vector<std::string> numbers;
  const std::string key = "\"position\"";
  for (auto at = json.find(key); at != std::string::npos; at = json.find(key, at + key.size())) {
    const auto open = json.find('[', at), close = json.find(']', at);
    std::string number;
    for (char c : json.substr(open + 1, close - open - 1) + ",") {
      if (c == ',') {
        numbers.push_back(number);
        number.clear();
      } else if (!std::isspace(static_cast<unsigned char>(c))) {
        number += c;
      }
    }
  }
  return numbers;
}
} // namespace

int MarkupsIOTest(int, char*[])
{
  return brainshift::testing::runTest("MarkupsIOTest", [&] {
    const fs::path folder = testing::temporaryFolder("MarkupsIOTest");

    const std::vector<NamedPoint> points = {{"nasion", point(10, -20, 30)},
                                            {"left tragus", point(71.333333333333329, 0.1, -5.0)},
                                            {"vertex \"top\"", point(-0.0, 1e-3, 95.125)}};
    const fs::path file = folder / "points.mrk.json";
    writeMarkupsJson(points, file);
    const std::vector<NamedPoint> read = readMarkupsJson(file);
    BS_CHECK(read.size() == points.size());
    for (std::size_t i = 0; i < points.size(); ++i) {
      BS_CHECK_MSG(read[i].name == points[i].name, read[i].name);
      BS_CHECK_MSG(read[i].position == points[i].position, read[i].position << " for " << points[i].position);
    }

    // What Slicer needs in the text: the schema, LPS, and floating-point positions ("10.0").
    const std::string json = readTextFile(file);
    BS_CHECK(json.find("\"@schema\"") != std::string::npos);
    BS_CHECK(json.find("markups-schema-v1.0.3.json#") != std::string::npos);
    BS_CHECK(json.find("\"coordinateSystem\": \"LPS\"") != std::string::npos);
    BS_CHECK(json.find("\"type\": \"Fiducial\"") != std::string::npos);
    const std::vector<std::string> numbers = positionNumbers(json);
    BS_CHECK_MSG(numbers.size() == 9, numbers.size() << " position numbers");
    BS_CHECK_MSG(numbers[0] == "10.0" && numbers[1] == "-20.0" && numbers[2] == "30.0",
                 numbers[0] << " " << numbers[1] << " " << numbers[2]);
    for (const std::string& number : numbers) {
      BS_CHECK_MSG(number.find_first_of(".eE") != std::string::npos, "'" << number << "' is an integer in JSON");
    }

    // A file in RAS (and one without a coordinate system, which means LPS).
    const fs::path ras = folder / "ras.mrk.json";
    std::ofstream(ras) << R"({"@schema": "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/Schema/markups-schema-v1.0.3.json#",
      "markups": [{"type": "Fiducial", "coordinateSystem": "RAS", "controlPoints": [
        {"id": "1", "label": "A", "position": [1.5, -2.5, 3.25]},
        {"id": "2", "label": "B", "position": [-10.0, 20.0, -30.0]}]}]})";
    const std::vector<NamedPoint> converted = readMarkupsJson(ras);
    BS_CHECK(converted.size() == 2);
    BS_CHECK(converted[0].name == "A" && converted[0].position == point(-1.5, 2.5, 3.25));
    BS_CHECK(converted[1].name == "B" && converted[1].position == point(10, -20, -30));
    const fs::path unstated = folder / "unstated.mrk.json";
    std::ofstream(unstated) << R"({"markups": [{"type": "Fiducial", "controlPoints": [{"label": "C", "position": [1.0, 2.0, 3.0]}]}]})";
    BS_CHECK(readMarkupsJson(unstated).at(0).position == point(1, 2, 3));

    // Unusable files are input errors naming the file.
    const fs::path broken = folder / "broken.mrk.json";
    std::ofstream(broken) << "{\"markups\": [";
    BS_CHECK_THROWS(readMarkupsJson(broken), InputError, broken.string());
    const fs::path other = folder / "other.mrk.json";
    std::ofstream(other) << R"({"markups": [{"coordinateSystem": "IJK", "controlPoints": []}]})";
    BS_CHECK_THROWS(readMarkupsJson(other), InputError, "IJK");
  });
}
