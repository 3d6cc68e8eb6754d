#include "NonrigidUpdateTrust.h"

#include "DistanceMaps.h"

#include <algorithm>
#include <array>
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

bool isBrainLabel(LabelPixel l)
{
  return l == 2 || l == 3 || l == 4;
}

/// The box of voxel indices (first, one past the last, per axis) that holds the brain of every
/// given map, grown by `margin` voxels per axis and clamped to the grid; empty (first == last on
/// an axis) when no map has brain.
struct IndexBox {
  std::array<std::size_t, 3> first{}, last{};
  std::size_t voxels() const { return (last[0] - first[0]) * (last[1] - first[1]) * (last[2] - first[2]); }
};

IndexBox brainBox(const std::vector<const LabelImage*>& maps, const ImageGeometry& grid, const std::array<std::size_t, 3>& margin)
{
  const std::size_t nx = grid.size[0], ny = grid.size[1], nz = grid.size[2];
  std::array<std::size_t, 3> low{nx, ny, nz}, high{0, 0, 0};
  for (const LabelImage* labels : maps) {
    const LabelPixel* l = labels->GetBufferPointer();
    for (std::size_t z = 0, i = 0; z < nz; ++z) {
      for (std::size_t y = 0; y < ny; ++y) {
        for (std::size_t x = 0; x < nx; ++x, ++i) {
          if (!isBrainLabel(l[i])) continue;
          const std::array<std::size_t, 3> at{x, y, z};
          for (int a = 0; a < 3; ++a) {
            low[a] = std::min(low[a], at[a]);
            high[a] = std::max(high[a], at[a] + 1);
          }
        }
      }
    }
  }
  IndexBox box;
  for (int a = 0; a < 3; ++a) {
    if (high[a] <= low[a]) return box;
    box.first[a] = low[a] > margin[a] ? low[a] - margin[a] : 0;
    box.last[a] = std::min<std::size_t>(grid.size[a], high[a] + margin[a]);
  }
  return box;
}

/// The voxels of `box` (an image of its own whose voxels lie where they lie on the full grid) on
/// either side of a face between brain (labels 2, 3, 4) and other voxels of any of `maps` (faces on
/// the grid's edge are none: beyond it nothing is known).
MaskPointer brainBoundaryVoxelsIn(const std::vector<const LabelImage*>& maps, const ImageGeometry& grid, const IndexBox& box)
{
  ImageGeometry cropped = grid;
  LabelImage::IndexType corner;
  for (int a = 0; a < 3; ++a) {
    cropped.size[a] = box.last[a] - box.first[a];
    corner[a] = itk::IndexValueType(box.first[a]);
  }
  maps.front()->TransformIndexToPhysicalPoint(corner, cropped.origin);
  MaskPointer boundary = cropped.allocate<MaskImage>();
  unsigned char* b = boundary->GetBufferPointer();
  std::fill(b, b + box.voxels(), 0);
  const std::size_t strides[3] = {1, grid.size[0], grid.size[0] * grid.size[1]};
  for (const LabelImage* labels : maps) {
    const LabelPixel* l = labels->GetBufferPointer();
    for (std::size_t z = box.first[2], j = 0; z < box.last[2]; ++z) {
      for (std::size_t y = box.first[1]; y < box.last[1]; ++y) {
        for (std::size_t x = box.first[0]; x < box.last[0]; ++x, ++j) {
          if (b[j]) continue;
          const std::size_t i = (z * grid.size[1] + y) * grid.size[0] + x;
          const bool brain = isBrainLabel(l[i]);
          const std::size_t at[3] = {x, y, z};
          for (int a = 0; a < 3 && !b[j]; ++a) {
            if (at[a] > 0 && isBrainLabel(l[i - strides[a]]) != brain) b[j] = 1;
            else if (at[a] + 1 < grid.size[a] && isBrainLabel(l[i + strides[a]]) != brain) b[j] = 1;
          }
        }
      }
    }
  }
  return boundary;
}

/// Per voxel: 1 band (within the band's half width of a voxel on either side of any map's brain
/// boundary), 2 interior (brain in the first of the classification and the rigidly warped labels,
/// beyond the band), 0 elsewhere. The band: the voxels within its half width of the boundary voxels
/// of all the maps (voxelsWithin: what their distance map thresholded there gives), in the box that
/// holds every map's brain grown by the band and two voxels: beyond it no voxel is within the band
/// of a boundary, nor inside a brain.
std::vector<unsigned char> regionsOf(const NonrigidUpdateTrustInputs& in, double bandHalfWidthMm, std::size_t n)
{
  std::vector<unsigned char> region(n, 0);
  const LabelImage* interiorSource =
    in.intraopLabels ? in.intraopLabels : in.labelsWarpedByRigid ? in.labelsWarpedByRigid : in.labelsWarpedByUpdate;
  std::vector<const LabelImage*> maps;
  for (const LabelImage* labels : {in.intraopLabels, in.labelsWarpedByUpdate, in.labelsWarpedByRigid}) {
    if (labels) maps.push_back(labels);
  }
  const ImageGeometry grid = ImageGeometry::of(maps.front());
  std::array<std::size_t, 3> margin{};
  for (int a = 0; a < 3; ++a) margin[a] = std::size_t(std::ceil(bandHalfWidthMm / grid.spacing[a])) + 2;
  const IndexBox box = brainBox(maps, grid, margin);
  if (box.voxels() == 0) return region;
  const MaskPointer band = voxelsWithin(brainBoundaryVoxelsIn(maps, grid, box), bandHalfWidthMm);
  const unsigned char* inBand = band->GetBufferPointer();
  const LabelPixel* interior = interiorSource->GetBufferPointer();
  for (std::size_t z = box.first[2], j = 0; z < box.last[2]; ++z) {
    for (std::size_t y = box.first[1]; y < box.last[1]; ++y) {
      const std::size_t row = (z * grid.size[1] + y) * grid.size[0];
      for (std::size_t x = box.first[0]; x < box.last[0]; ++x, ++j) {
        if (inBand[j]) region[row + x] = 1;
        else if (isBrainLabel(interior[row + x])) region[row + x] = 2;
      }
    }
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

/// Where the two mappings differ by `movedMm` or more and the scan's classification or the update
/// shows brain (empty when the fields are not given). Not where neither does: the gap a sunken
/// brain left and the skull above it have no preoperative counterpart the update could move, and
/// the update's field reaches into them only to carry the brain's boundary across.
std::vector<bool> movedVoxels(const NonrigidUpdateTrustInputs& in, double movedMm, std::size_t n)
{
  std::vector<bool> moved;
  if (!in.updateField || !in.rigidField) return moved;
  moved.assign(n, false);
  const DisplacementVector* u = in.updateField->GetBufferPointer();
  const DisplacementVector* r = in.rigidField->GetBufferPointer();
  const LabelPixel* scan = in.intraopLabels ? in.intraopLabels->GetBufferPointer() : nullptr;
  const LabelPixel* shown = in.labelsWarpedByUpdate ? in.labelsWarpedByUpdate->GetBufferPointer() : nullptr;
  for (std::size_t i = 0; i < n; ++i) {
    const bool brain = (!scan && !shown) || (scan && isBrainLabel(scan[i])) || (shown && isBrainLabel(shown[i]));
    moved[i] = brain && (u[i] - r[i]).GetNorm() >= movedMm;
  }
  return moved;
}

std::string figure(const char* format, double a, double b = 0, double c = 0)
{
  char text[256];
  std::snprintf(text, sizeof text, format, a, b, c);
  return text;
}

/// A small loss where the update moves the brain against a clear gain inside it (the parameters'
/// mixed evidence); only when the moved region decides.
bool isMixedEvidence(const NonrigidUpdateTrustAssessment& a, bool movedScored, const NonrigidUpdateTrustParameters& p)
{
  return movedScored && a.moved.gain() >= p.mixedLossDownTo && a.interior.voxels >= p.minimumVoxels &&
         a.interior.gain() >= p.mixedInteriorGainFrom;
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
    if (decisive.gain() < p.rejectGainBelow && isMixedEvidence(a, movedScored, p)) {
      downgrade(UpdateTrust::Doubtful, "the image under the update matches the intraoperative scan a little worse than the rigid result " +
                                         figures + figure(", but better inside the brain (%.3f against %.3f)", a.interior.nonrigid,
                                                          a.interior.rigid));
    } else if (decisive.gain() < p.rejectGainBelow) {
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
