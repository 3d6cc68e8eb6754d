#pragma once
// Target registration error of an intraop_to_preop transform against landmark pairs: each
// intraoperative point is mapped through the transform and compared with its preoperative point.
#include "LandmarkIO.h"
#include "TransformIO.h"

#include <map>
#include <string>
#include <vector>

namespace brainshift {

struct ErrorStatistics {
  double meanMm = 0, medianMm = 0, p95Mm = 0, maxMm = 0;
  std::size_t count = 0;
};

struct RegistrationError {
  ErrorStatistics overall;
  std::vector<std::pair<std::string, double>> pairs; ///< name, error in mm, in file order
  /// By the name's prefix before its last '-' ("brain-03" -> "brain"): e.g. the error near the
  /// cavity, or the rigid error on the head, reported apart.
  std::map<std::string, ErrorStatistics> groups;
};

/// Percentiles interpolate linearly between order statistics (as numpy's default).
ErrorStatistics errorStatistics(std::vector<double> errors);

RegistrationError evaluateTransform(const SpatialTransform& intraopToPreop, const std::vector<LandmarkPair>& pairs);

/// {"mean_mm", "median_mm", "p95_mm", "max_mm", "pairs": [{"name", "error_mm"}], "groups": {...}}
std::string toJsonText(const RegistrationError& error);

} // namespace brainshift
