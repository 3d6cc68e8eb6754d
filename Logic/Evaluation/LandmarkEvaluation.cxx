#include "LandmarkEvaluation.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace brainshift {

ErrorStatistics errorStatistics(std::vector<double> errors)
{
  ErrorStatistics s;
  s.count = errors.size();
  if (errors.empty()) return s;
  std::sort(errors.begin(), errors.end());
  auto percentile = [&](double q) {
    const double position = q * double(errors.size() - 1);
    const std::size_t below = std::size_t(std::floor(position));
    const std::size_t above = std::min(below + 1, errors.size() - 1);
    return errors[below] + (position - double(below)) * (errors[above] - errors[below]);
  };
  s.meanMm = std::accumulate(errors.begin(), errors.end(), 0.0) / double(errors.size());
  s.medianMm = percentile(0.5);
  s.p95Mm = percentile(0.95);
  s.maxMm = errors.back();
  return s;
}

RegistrationError evaluateTransform(const SpatialTransform& intraopToPreop, const std::vector<LandmarkPair>& pairs)
{
  if (pairs.empty()) throw std::invalid_argument("no landmark pairs to evaluate");
  RegistrationError result;
  std::vector<double> all;
  std::map<std::string, std::vector<double>> grouped;
  for (const LandmarkPair& pair : pairs) {
    const PhysicalPoint mapped = intraopToPreop.TransformPoint(pair.intraop);
    const double error = mapped.EuclideanDistanceTo(pair.preop);
    result.pairs.emplace_back(pair.name, error);
    all.push_back(error);
    const auto dash = pair.name.rfind('-');
    if (dash != std::string::npos && dash > 0) grouped[pair.name.substr(0, dash)].push_back(error);
  }
  result.overall = errorStatistics(all);
  for (auto& [group, errors] : grouped) result.groups[group] = errorStatistics(errors);
  return result;
}

std::string toJsonText(const RegistrationError& error)
{
  auto statistics = [](const ErrorStatistics& s) {
    return nlohmann::json{{"mean_mm", s.meanMm}, {"median_mm", s.medianMm}, {"p95_mm", s.p95Mm},
                          {"max_mm", s.maxMm}, {"count", s.count}};
  };
  nlohmann::json document = statistics(error.overall);
  document["pairs"] = nlohmann::json::array();
  for (const auto& [name, mm] : error.pairs) document["pairs"].push_back({{"name", name}, {"error_mm", mm}});
  document["groups"] = nlohmann::json::object();
  for (const auto& [group, s] : error.groups) document["groups"][group] = statistics(s);
  return document.dump(2) + "\n";
}

} // namespace brainshift
