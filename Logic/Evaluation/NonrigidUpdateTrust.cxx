#include "NonrigidUpdateTrust.h"

#include "DistanceMaps.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace brainshift {

std::string trustName(UpdateTrust trust)
{
  switch (trust) {
  case UpdateTrust::Trusted: return "trusted";
  case UpdateTrust::Doubtful: return "doubtful";
  case UpdateTrust::Rejected: return "rejected";
  }
  return "unknown";
}

double correlationRatio(const std::vector<float>& values, const std::vector<float>& predictor, unsigned bins, double low,
                        double high)
{
  if (values.size() != predictor.size()) throw std::invalid_argument("correlationRatio: values and predictor differ in length");
  if (values.empty() || bins == 0) return 0;
  std::vector<double> count(bins, 0), sum(bins, 0), sumSquares(bins, 0);
  const double width = high > low ? (high - low) / bins : 1.0;
  double total = 0, totalSquares = 0;
  for (std::size_t i = 0; i < values.size(); ++i) {
    const double bin = std::floor((double(predictor[i]) - low) / width);
    const unsigned b = unsigned(std::clamp(bin, 0.0, double(bins - 1)));
    const double v = values[i];
    count[b] += 1;
    sum[b] += v;
    sumSquares[b] += v * v;
    total += v;
    totalSquares += v * v;
  }
  const double n = double(values.size());
  const double variance = totalSquares - total * total / n;
  if (!(variance > 1e-12 * std::max(1.0, totalSquares))) return 0;
  double within = 0;
  for (unsigned b = 0; b < bins; ++b) {
    if (count[b] > 0) within += sumSquares[b] - sum[b] * sum[b] / count[b];
  }
  return std::clamp(1.0 - within / variance, 0.0, 1.0);
}

namespace {
using MaskPointer = MaskImage::Pointer;

template <class TImage>
void checkOnGrid(const TImage* image, const ImageGeometry& grid, const char* name)
{
  if (!image) return;
  if (!ImageGeometry::of(image).sameGridAs(grid)) {
    throw std::invalid_argument(std::string("trust assessment: ") + name + " (" + ImageGeometry::of(image).describe() +
                                ") is not on the intraoperative grid (" + grid.describe() + ")");
  }
}

MaskPointer brainMaskOf(const LabelImage& labels)
{
  MaskPointer mask = ImageGeometry::of(&labels).allocate<MaskImage>();
  const LabelPixel* l = labels.GetBufferPointer();
  unsigned char* m = mask->GetBufferPointer();
  const std::size_t n = labels.GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) m[i] = (l[i] == 2 || l[i] == 3 || l[i] == 4) ? 1 : 0;
  return mask;
}

/// Per voxel: 1 band (near any map's brain boundary), 2 interior (inside the first of the
/// classification and the rigidly warped labels, beyond the band), 0 elsewhere.
std::vector<unsigned char> regionsOf(const NonrigidUpdateTrustInputs& in, double bandHalfWidthMm, std::size_t n)
{
  std::vector<unsigned char> region(n, 0);
  const LabelImage* interiorSource =
    in.intraopLabels ? in.intraopLabels : in.labelsWarpedByRigid ? in.labelsWarpedByRigid : in.labelsWarpedByUpdate;
  std::vector<float> interiorDistance;
  for (const LabelImage* labels : {in.intraopLabels, in.labelsWarpedByUpdate, in.labelsWarpedByRigid}) {
    if (!labels) continue;
    const ScalarImage::Pointer distance = boundaryDistanceMm(brainMaskOf(*labels));
    const float* d = distance->GetBufferPointer();
    for (std::size_t i = 0; i < n; ++i) {
      if (std::abs(d[i]) <= bandHalfWidthMm) region[i] = 1;
    }
    if (labels == interiorSource) interiorDistance.assign(d, d + n);
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (region[i] == 0 && interiorDistance[i] < 0) region[i] = 2;
  }
  return region;
}

double quantile(std::vector<float> values, double q)
{
  if (values.empty()) return 0;
  const std::size_t k = std::min(values.size() - 1, std::size_t(q * double(values.size() - 1)));
  std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(k), values.end());
  return values[k];
}

/// eta^2 of both warps on the voxels `selected`, with bins over the robust range of both.
RegionSimilarity similarityOn(const NonrigidUpdateTrustInputs& in, const std::vector<std::size_t>& selected, unsigned bins,
                              bool bothDirections)
{
  RegionSimilarity s;
  s.voxels = selected.size();
  if (selected.empty()) return s;
  std::vector<float> intraop, byUpdate, byRigid;
  intraop.reserve(selected.size());
  byUpdate.reserve(selected.size());
  byRigid.reserve(selected.size());
  const float* i0 = in.intraop->GetBufferPointer();
  const float* u0 = in.warpedByUpdate->GetBufferPointer();
  const float* r0 = in.warpedByRigid->GetBufferPointer();
  for (std::size_t i : selected) {
    intraop.push_back(i0[i]);
    byUpdate.push_back(u0[i]);
    byRigid.push_back(r0[i]);
  }
  std::vector<float> both(byUpdate);
  both.insert(both.end(), byRigid.begin(), byRigid.end());
  const double low = quantile(both, 0.005), high = quantile(both, 0.995);
  s.nonrigid = correlationRatio(intraop, byUpdate, bins, low, high);
  s.rigid = correlationRatio(intraop, byRigid, bins, low, high);
  if (bothDirections) {
    // And the warped preoperative image given the intraoperative one: a T1's dark CSF, bone and
    // air are bright CSF and fluid, dark bone and air in a T2, no function of the T1 but the other
    // way round. The direction in which the update gains more is the one reported (measured on
    // the built-in cases: in T1 the two gains differ by less than 0.01; in T2 the update's gain
    // given the T1 was -0.11 to -0.17, given the T2 +0.005 to +0.08, the update 0.9 against 1.6-1.8 mm).
    const double lowIntraop = quantile(intraop, 0.005), highIntraop = quantile(intraop, 0.995);
    RegionSimilarity reverse = s;
    reverse.nonrigid = correlationRatio(byUpdate, intraop, bins, lowIntraop, highIntraop);
    reverse.rigid = correlationRatio(byRigid, intraop, bins, lowIntraop, highIntraop);
    reverse.preoperativeGivenIntraoperative = true;
    if (reverse.gain() > s.gain()) return reverse;
  }
  return s;
}

/// Where the two mappings differ by `movedMm` or more (empty when the fields are not given).
std::vector<bool> movedVoxels(const NonrigidUpdateTrustInputs& in, double movedMm, std::size_t n)
{
  std::vector<bool> moved;
  if (!in.updateField || !in.rigidField) return moved;
  moved.assign(n, false);
  const DisplacementVector* u = in.updateField->GetBufferPointer();
  const DisplacementVector* r = in.rigidField->GetBufferPointer();
  for (std::size_t i = 0; i < n; ++i) moved[i] = (u[i] - r[i]).GetNorm() >= movedMm;
  return moved;
}

std::string figure(const char* format, double a, double b = 0, double c = 0)
{
  char text[256];
  std::snprintf(text, sizeof text, format, a, b, c);
  return text;
}

void judge(NonrigidUpdateTrustAssessment& a, const NonrigidUpdateTrustInputs& in, const NonrigidUpdateTrustParameters& p)
{
  auto downgrade = [&a](UpdateTrust to, const std::string& reason) {
    a.trust = std::max(a.trust, to);
    a.reasons.push_back(reason);
  };
  const bool movedScored = a.moved.voxels >= p.minimumVoxels;
  const RegionSimilarity& decisive = movedScored ? a.moved : a.band;
  const char* where = movedScored ? "where the update moves the brain" : "near the brain boundary";
  if (decisive.voxels >= p.minimumVoxels) {
    const std::string figures = figure("(correlation ratio %.3f against %.3f) ", decisive.nonrigid, decisive.rigid) + where;
    if (decisive.gain() < p.rejectGainBelow) {
      downgrade(UpdateTrust::Rejected, "the image under the update matches the intraoperative scan worse than the rigid result " + figures);
    } else if (decisive.gain() < p.doubtGainBelow) {
      downgrade(UpdateTrust::Doubtful, "the image under the update matches the intraoperative scan hardly better than the rigid result " +
                                         figures);
    }
  } else {
    downgrade(UpdateTrust::Doubtful, "too few voxels near the brain boundary to compare the update with the rigid result (" +
                                       std::to_string(decisive.voxels) + ")");
  }
  if (in.surfaceNodes && in.unmatchedSurfaceNodes && *in.surfaceNodes > 0) {
    a.unmatchedShare = double(*in.unmatchedSurfaceNodes) / double(*in.surfaceNodes);
    const std::string reason = figure("%.0f %% of the surface nodes found no boundary to match and were left free",
                                      100 * a.unmatchedShare);
    if (a.unmatchedShare > p.rejectUnmatchedShare) downgrade(UpdateTrust::Rejected, reason);
    else if (a.unmatchedShare > p.doubtUnmatchedShare) downgrade(UpdateTrust::Doubtful, reason);
  }
  if (in.surfaceMeanResidualMm && *in.surfaceMeanResidualMm > p.doubtResidualMm) {
    downgrade(UpdateTrust::Doubtful, figure("the surface stays %.2f mm from the boundary it matched (mean)", *in.surfaceMeanResidualMm));
  }
  if (in.foldedVoxels && in.meshVoxels && *in.meshVoxels > 0) {
    a.foldedShare = double(*in.foldedVoxels) / double(*in.meshVoxels);
    const std::string reason = figure("the deformation folds in %.0f voxels (%.2f %% of the brain)", double(*in.foldedVoxels),
                                      100 * a.foldedShare);
    if (a.foldedShare > p.rejectFoldedShare) downgrade(UpdateTrust::Rejected, reason);
    else if (a.foldedShare > p.doubtFoldedShare) downgrade(UpdateTrust::Doubtful, reason);
  }
}
} // namespace

NonrigidUpdateTrustAssessment assessNonrigidUpdate(const NonrigidUpdateTrustInputs& in, const NonrigidUpdateTrustParameters& p)
{
  if (!in.intraop || !in.warpedByUpdate || !in.warpedByRigid) {
    throw std::invalid_argument("trust assessment: the intraoperative image and both warped preoperative images are needed");
  }
  if (!in.intraopLabels && !in.labelsWarpedByUpdate && !in.labelsWarpedByRigid) {
    throw std::invalid_argument("trust assessment: a label map is needed to place the brain boundary");
  }
  const ImageGeometry grid = ImageGeometry::of(in.intraop);
  checkOnGrid(in.warpedByUpdate, grid, "the image warped by the update");
  checkOnGrid(in.warpedByRigid, grid, "the image warped by the rigid transform");
  checkOnGrid(in.intraopLabels, grid, "the intraoperative labels");
  checkOnGrid(in.labelsWarpedByUpdate, grid, "the labels warped by the update");
  checkOnGrid(in.labelsWarpedByRigid, grid, "the labels warped by the rigid transform");
  checkOnGrid(in.updateField, grid, "the update's field");
  checkOnGrid(in.rigidField, grid, "the rigid field");
  const std::size_t n = grid.numberOfVoxels();
  const std::vector<unsigned char> region = regionsOf(in, p.bandHalfWidthMm, n);
  const std::vector<bool> moved = movedVoxels(in, p.movedMm, n);
  std::vector<std::size_t> band, interior, movedSelected;
  for (std::size_t i = 0; i < n; ++i) {
    if (region[i] == 1) band.push_back(i);
    if (region[i] == 2) interior.push_back(i);
    if (region[i] != 0 && !moved.empty() && moved[i]) movedSelected.push_back(i);
  }
  NonrigidUpdateTrustAssessment a;
  a.band = similarityOn(in, band, p.bins, p.bothDirections);
  a.interior = similarityOn(in, interior, p.bins, p.bothDirections);
  a.moved = similarityOn(in, movedSelected, p.bins, p.bothDirections);
  judge(a, in, p);
  return a;
}

} // namespace brainshift
