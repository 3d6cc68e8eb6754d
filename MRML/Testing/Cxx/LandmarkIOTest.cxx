// The landmark CSV of ../shared/CONTRACT.md: an exact round trip under the contract's header, and
// errors that point at the file and line.
#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "LandmarkIO.h"
#include "SyntheticData.h"

#include <fstream>
#include <vector>

namespace {
using namespace brainshift;
namespace fs = std::filesystem;
using brainshift::testing::point;

constexpr const char* ContractHeader = "name,preop_x,preop_y,preop_z,intraop_x,intraop_y,intraop_z";

fs::path writeText(const fs::path& path, const std::string& text)
{
  std::ofstream(path, std::ios::binary) << text;
  return path;
}
} // namespace

int LandmarkIOTest(int, char*[])
{
  return brainshift::testing::runTest("LandmarkIOTest", [&] {
    const fs::path folder = testing::temporaryFolder("LandmarkIOTest");

    // Round trip: every double comes back bit for bit.
    const std::vector<LandmarkPair> pairs = {
      {"anterior horn", point(0.1, -90.25, 1.0 / 3.0), point(2.0 / 7.0, -88.5, 13.0)},
      {"AC", point(-1e-9, 123456.78901234567, -0.0), point(1e-300, 5e7, -71.123456789012345)},
      {"tumour_tip-2", point(-12.5, 37.75, 41.000000000000007), point(-12.25, 36.5, 40.875)}};
    const fs::path file = folder / "landmarks.csv";
    writeLandmarksCsv(pairs, file);
    const std::string text = readTextFile(file);
    BS_CHECK_MSG(text.substr(0, text.find('\n')) == ContractHeader, text.substr(0, text.find('\n')));
    const std::vector<LandmarkPair> read = readLandmarksCsv(file);
    BS_CHECK(read.size() == pairs.size());
    for (std::size_t i = 0; i < pairs.size(); ++i) {
      BS_CHECK(read[i].name == pairs[i].name);
      for (int k = 0; k < 3; ++k) {
        BS_CHECK_MSG(read[i].preop[k] == pairs[i].preop[k], pairs[i].name << " preop " << k);
        BS_CHECK_MSG(read[i].intraop[k] == pairs[i].intraop[k], pairs[i].name << " intraop " << k);
      }
    }
    // A name the CSV cannot hold is refused on writing.
    BS_CHECK_THROWS(writeLandmarksCsv({{"a,b", point(0, 0, 0), point(0, 0, 0)}}, folder / "comma.csv"),
                    std::invalid_argument, "a,b");

    // Quoted names may hold commas and quotes; spaces around fields are ignored.
    const fs::path quoted = writeText(folder / "quoted.csv", std::string(ContractHeader) +
                                                                 "\n\"left, upper\", 1, 2, 3, 4, 5, 6\n"
                                                                 "\"the \"\"notch\"\"\",-1,-2,-3,-4,-5,-6.5\n");
    const std::vector<LandmarkPair> quotedPairs = readLandmarksCsv(quoted);
    BS_CHECK(quotedPairs.size() == 2);
    BS_CHECK_MSG(quotedPairs[0].name == "left, upper", quotedPairs[0].name);
    BS_CHECK(quotedPairs[0].preop == point(1, 2, 3) && quotedPairs[0].intraop == point(4, 5, 6));
    BS_CHECK_MSG(quotedPairs[1].name == "the \"notch\"", quotedPairs[1].name);
    BS_CHECK(quotedPairs[1].intraop == point(-4, -5, -6.5));

    // Errors name the file and the line.
    const std::string header = std::string(ContractHeader) + "\n";
    const std::string good = "a,1,2,3,4,5,6\n";
    const struct {
      const char* fileName;
      std::string text;
      std::string where; // ":<line>" expected after the path
      const char* what;
    } badFiles[] = {
      {"wrong_header.csv", "name,x,y,z,x2,y2,z2\n" + good, ":1:", "header"},
      {"six_fields.csv", header + good + "b,1,2,3,4,5\n", ":3:", "6 fields"},
      {"not_a_number.csv", header + "a,1,abc,3,4,5,6\n", ":2:", "'abc'"},
      {"nan.csv", header + good + "b,1,2,3,nan,5,6\n", ":3:", "'nan'"},
      {"duplicate.csv", header + good + "b,0,0,0,0,0,0\n" + good, ":4:", "twice"},
    };
    for (const auto& bad : badFiles) {
      const fs::path path = writeText(folder / bad.fileName, bad.text);
      BS_CHECK_THROWS(readLandmarksCsv(path), InputError, path.string() + bad.where);
      BS_CHECK_THROWS(readLandmarksCsv(path), InputError, bad.what);
    }
    const fs::path onlyHeader = writeText(folder / "only_header.csv", header);
    BS_CHECK_THROWS(readLandmarksCsv(onlyHeader), InputError, onlyHeader.string());
    BS_CHECK_THROWS(readLandmarksCsv(onlyHeader), InputError, "no pairs");
    const fs::path missing = folder / "missing.csv";
    BS_CHECK_THROWS(readLandmarksCsv(missing), InputError, missing.string());
  });
}
