#include "IntensityStatistics.h"

#include <algorithm>
#include <stdexcept>

namespace brainshift {

std::vector<double> otsuThresholds(const float* values, std::size_t count, int classes, double lo, double hi,
                                   const unsigned char* mask)
{
  if (classes != 2 && classes != 3) throw std::invalid_argument("otsuThresholds: 2 or 3 classes");
  if (!(hi > lo)) return std::vector<double>(std::size_t(classes - 1), lo);
  constexpr int Bins = 256;
  std::vector<double> histogram(Bins, 0.0);
  double total = 0;
  for (std::size_t i = 0; i < count; ++i) {
    if (mask && !mask[i]) continue;
    const int b = std::clamp(int((values[i] - lo) / (hi - lo) * (Bins - 1) + 0.5), 0, Bins - 1);
    histogram[b] += 1;
    total += 1;
  }
  if (total == 0) return std::vector<double>(std::size_t(classes - 1), lo);
  auto binValue = [&](int b) { return lo + (hi - lo) * b / (Bins - 1); };
  std::vector<double> cumulative(Bins + 1, 0), cumulativeMean(Bins + 1, 0);
  for (int b = 0; b < Bins; ++b) {
    const double p = histogram[b] / total;
    cumulative[b + 1] = cumulative[b] + p;
    cumulativeMean[b + 1] = cumulativeMean[b] + p * binValue(b);
  }
  // Between-class variance, up to a constant: the sum over classes of mean^2 * weight.
  auto classScore = [&](int from, int to) {
    const double w = cumulative[to] - cumulative[from];
    if (w <= 0) return 0.0;
    const double m = cumulativeMean[to] - cumulativeMean[from];
    return m * m / w;
  };
  double best = -1;
  std::vector<double> thresholds;
  if (classes == 2) {
    for (int t = 1; t < Bins; ++t) {
      const double score = classScore(0, t) + classScore(t, Bins);
      if (score > best) {
        best = score;
        thresholds = {binValue(t)};
      }
    }
  } else {
    for (int t1 = 1; t1 < Bins - 1; ++t1) {
      for (int t2 = t1 + 1; t2 < Bins; ++t2) {
        const double score = classScore(0, t1) + classScore(t1, t2) + classScore(t2, Bins);
        if (score > best) {
          best = score;
          thresholds = {binValue(t1), binValue(t2)};
        }
      }
    }
  }
  return thresholds;
}

} // namespace brainshift
