#include "UncertaintyEvaluation.h"

#include <itkNearestNeighborInterpolateImageFunction.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <vector>

namespace brainshift {
namespace {
/// Ranks (ties averaged).
std::vector<double> ranks(const std::vector<double>& values)
{
  std::vector<std::size_t> order(values.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&values](std::size_t a, std::size_t b) { return values[a] < values[b]; });
  std::vector<double> rank(values.size());
  for (std::size_t i = 0; i < order.size();) {
    std::size_t j = i;
    while (j + 1 < order.size() && values[order[j + 1]] == values[order[i]]) ++j;
    for (std::size_t k = i; k <= j; ++k) rank[order[k]] = 0.5 * double(i + j);
    i = j + 1;
  }
  return rank;
}

double pearson(const std::vector<double>& a, const std::vector<double>& b)
{
  const double n = double(a.size());
  const double ma = std::accumulate(a.begin(), a.end(), 0.0) / n, mb = std::accumulate(b.begin(), b.end(), 0.0) / n;
  double sab = 0, saa = 0, sbb = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  return saa > 0 && sbb > 0 ? sab / std::sqrt(saa * sbb) : 0.0;
}
} // namespace

UncertaintyValidation validateUncertainty(const DisplacementFieldImage& update, const SpatialTransform& truth, const ScalarImage& estimate,
                                          const LabelImage& truthLabels, const std::set<LabelPixel>& brainLabels, unsigned stride)
{
  const auto size = update.GetLargestPossibleRegion().GetSize();
  if (estimate.GetLargestPossibleRegion().GetSize() != size) throw std::invalid_argument("the confidence map is not on the update's grid");
  auto labelAt = itk::NearestNeighborInterpolateImageFunction<LabelImage, double>::New();
  labelAt->SetInputImage(&truthLabels);
  std::vector<double> errors, estimates;
  stride = std::max(1u, stride);
  UncertaintyValidation v;
  v.trueError = ScalarImage::New();
  v.trueError->CopyInformation(&update);
  v.trueError->SetRegions(update.GetLargestPossibleRegion());
  v.trueError->Allocate();
  v.trueError->FillBuffer(0.0f);
  for (itk::IndexValueType z = 0; z < itk::IndexValueType(size[2]); ++z)
    for (itk::IndexValueType y = 0; y < itk::IndexValueType(size[1]); ++y)
      for (itk::IndexValueType x = 0; x < itk::IndexValueType(size[0]); ++x) {
        const itk::Index<3> index{{x, y, z}};
        PhysicalPoint point;
        update.TransformIndexToPhysicalPoint(index, point);
        const auto d = update.GetPixel(index);
        const PhysicalPoint expected = truth.TransformPoint(point);
        double e2 = 0;
        for (int a = 0; a < 3; ++a) e2 += (point[a] + d[a] - expected[a]) * (point[a] + d[a] - expected[a]);
        v.trueError->SetPixel(index, float(std::sqrt(e2)));
      }
  for (itk::IndexValueType z = 0; z < itk::IndexValueType(size[2]); z += stride)
    for (itk::IndexValueType y = 0; y < itk::IndexValueType(size[1]); y += stride)
      for (itk::IndexValueType x = 0; x < itk::IndexValueType(size[0]); x += stride) {
        const itk::Index<3> index{{x, y, z}};
        PhysicalPoint point;
        update.TransformIndexToPhysicalPoint(index, point);
        if (!labelAt->IsInsideBuffer(point) || !brainLabels.count(LabelPixel(labelAt->Evaluate(point)))) continue;
        errors.push_back(v.trueError->GetPixel(index));
        estimates.push_back(estimate.GetPixel(index));
      }
  v.voxels = errors.size();
  if (errors.size() < 10) return v;
  v.rankCorrelation = pearson(ranks(errors), ranks(estimates));
  v.meanTrueErrorMm = std::accumulate(errors.begin(), errors.end(), 0.0) / double(errors.size());
  v.meanEstimateMm = std::accumulate(estimates.begin(), estimates.end(), 0.0) / double(estimates.size());
  std::size_t below = 0, reliable = 0, above = 0;
  double aboveError = 0;
  for (std::size_t i = 0; i < errors.size(); ++i) {
    if (estimates[i] < 1.0) {
      ++below;
      reliable += errors[i] < 1.5;
    }
    if (estimates[i] >= 2.0) {
      ++above;
      aboveError += errors[i];
    }
  }
  v.shareCalledBelow1Mm = double(below) / double(errors.size());
  v.calledBelow1MmTrulyBelow1_5Mm = below ? double(reliable) / double(below) : 1.0;
  v.trueErrorWhereCalledAbove2MmMm = above ? aboveError / double(above) : 0.0;
  return v;
}

} // namespace brainshift
