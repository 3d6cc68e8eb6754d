// Target registration error: statistics against values computed by hand, a known translation,
// groups by name prefix, and the JSON keys of ../shared/CONTRACT.md.
#include "BrainShiftTestingSupport.h"
#include "LandmarkEvaluation.h"

#include <itkTranslationTransform.h>
#include <nlohmann/json.hpp>

int LandmarkEvaluationTest(int, char*[])
{
  return brainshift::testing::runTest("LandmarkEvaluationTest", [] {
    using namespace brainshift;
    // Percentiles interpolate between order statistics: for 1, 2, 3, 4, 10 the 95th lies 0.8 of
    // the way from 4 to 10.
    const ErrorStatistics s = errorStatistics({10, 2, 4, 1, 3});
    BS_CHECK_NEAR(s.meanMm, 4.0, 1e-12);
    BS_CHECK_NEAR(s.medianMm, 3.0, 1e-12);
    BS_CHECK_NEAR(s.p95Mm, 8.8, 1e-12);
    BS_CHECK_NEAR(s.maxMm, 10.0, 1e-12);
    BS_CHECK(s.count == 5);
    const ErrorStatistics even = errorStatistics({1, 2, 3, 4});
    BS_CHECK_NEAR(even.medianMm, 2.5, 1e-12);

    // A transform that maps every intraop point 3 mm left and 4 mm posterior of its preop point:
    // every error is 5 mm, except the pair that was placed to be exact.
    auto translation = itk::TranslationTransform<double, 3>::New();
    itk::TranslationTransform<double, 3>::OutputVectorType offset;
    offset[0] = 3;
    offset[1] = 4;
    offset[2] = 0;
    translation->SetOffset(offset);
    std::vector<LandmarkPair> pairs;
    for (int i = 0; i < 4; ++i) {
      LandmarkPair pair;
      pair.name = (i < 2 ? "brain-0" : "head-0") + std::to_string(i);
      pair.intraop[0] = 10.0 * i;
      pair.intraop[1] = -5.0 * i;
      pair.intraop[2] = 2.0 * i;
      pair.preop = pair.intraop;
      if (i != 3) {
        pair.preop[0] += 6; // mapped point is at +3: 3 mm off along x ...
        pair.preop[1] += 8; // ... and 4 mm along y
      } else {
        pair.preop[0] += 3;
        pair.preop[1] += 4;
      }
      pairs.push_back(pair);
    }
    const RegistrationError error = evaluateTransform(*translation, pairs);
    BS_CHECK_NEAR(error.pairs[0].second, 5.0, 1e-12);
    BS_CHECK_NEAR(error.pairs[3].second, 0.0, 1e-12);
    BS_CHECK(error.pairs[2].first == "head-02");
    BS_CHECK_NEAR(error.overall.meanMm, 15.0 / 4.0, 1e-12);
    BS_CHECK(error.groups.size() == 2);
    BS_CHECK_NEAR(error.groups.at("brain").meanMm, 5.0, 1e-12);
    BS_CHECK_NEAR(error.groups.at("head").meanMm, 2.5, 1e-12);

    const nlohmann::json json = nlohmann::json::parse(toJsonText(error));
    for (const char* key : {"mean_mm", "median_mm", "p95_mm", "max_mm", "pairs"}) BS_CHECK_MSG(json.contains(key), key);
    BS_CHECK(json["pairs"].size() == 4);
    BS_CHECK(json["pairs"][1]["name"] == "brain-01");
    BS_CHECK_NEAR(json["pairs"][1]["error_mm"].get<double>(), 5.0, 1e-12);
    BS_CHECK_THROWS(evaluateTransform(*translation, {}), std::invalid_argument, "no landmark");
  });
}
