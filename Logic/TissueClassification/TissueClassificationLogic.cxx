#include "TissueClassificationLogic.h"

#include "AtomicFile.h"
#include "Configuration.h"
#include "DistanceMaps.h"
#include "ParallelRanges.h"
#include "MarkupsIO.h"

#include <itkBSplineControlPointImageFilter.h>
#include <itkBinShrinkImageFilter.h>
#include <itkConnectedComponentImageFilter.h>
#include <itkLinearInterpolateImageFunction.h>
#include <itkN4BiasFieldCorrectionImageFilter.h>
#include <itkRelabelComponentImageFilter.h>
#include <itkShrinkImageFilter.h>

#include <nanoflann.hpp>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <queue>
#include <set>
#include <sstream>
#include <thread>
#include <utility>
#include <vector>

namespace brainshift {
namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;
enum : LabelPixel { Background = 0, Head = 1, Parenchyma = 2, Ventricles = 3, Tumour = 4 };

double secondsSince(Clock::time_point start)
{
  return std::chrono::duration<double>(Clock::now() - start).count();
}

/// The index -> physical mapping of a grid as one affine map: p = origin + M * index.
struct GridMap {
  double origin[3];
  double m[3][3];
  template <class TImage>
  explicit GridMap(const TImage& image)
  {
    for (int r = 0; r < 3; ++r) {
      origin[r] = image.GetOrigin()[r];
      for (int c = 0; c < 3; ++c) m[r][c] = image.GetDirection()(r, c) * image.GetSpacing()[c];
    }
  }
};

/// Signed distance (mm, negative inside) to one tissue of the preoperative labels, on a grid of
/// about 2 mm, sampled by continuous index.
struct TissueDistance {
  LabelPixel label;
  ScalarImage::Pointer distance;
  double deepestMm = 0; ///< how deep the tissue's interior goes (positive)
};

class DistanceSampler {
public:
  explicit DistanceSampler(const ScalarImage& image)
    : image_(image)
    , size_(image.GetLargestPossibleRegion().GetSize())
    , data_(image.GetBufferPointer())
  {
    // physical -> continuous index: inverse of origin + D * S * index.
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) inverse_[r][c] = image.GetDirection()(c, r) / image.GetSpacing()[r];
      origin_[r] = image.GetOrigin()[r];
    }
  }
  /// Where a point falls on the grid: the first corner's offset and the eight corners' weights
  /// (zero for a corner beyond a one-voxel-thin axis). The same for every map on this grid.
  struct Cell {
    std::size_t first = 0;
    double weight[8];
  };
  Cell cellAt(const double p[3]) const
  {
    double c[3];
    for (int r = 0; r < 3; ++r) {
      c[r] = inverse_[r][0] * (p[0] - origin_[0]) + inverse_[r][1] * (p[1] - origin_[1]) + inverse_[r][2] * (p[2] - origin_[2]);
      c[r] = std::clamp(c[r], 0.0, double(size_[r] - 1));
    }
    std::size_t b[3];
    double f[3];
    for (int r = 0; r < 3; ++r) {
      b[r] = std::min<std::size_t>(std::size_t(c[r]), size_[r] >= 2 ? size_[r] - 2 : 0);
      f[r] = size_[r] >= 2 ? c[r] - double(b[r]) : 0.0;
    }
    Cell cell;
    cell.first = b[0] + size_[0] * (b[1] + size_[1] * b[2]);
    for (int corner = 0; corner < 8; ++corner) {
      const int dx = corner & 1, dy = (corner >> 1) & 1, dz = (corner >> 2) & 1;
      const bool beyond = (dx && size_[0] < 2) || (dy && size_[1] < 2) || (dz && size_[2] < 2);
      cell.weight[corner] = beyond ? 0.0 : (dx ? f[0] : 1 - f[0]) * (dy ? f[1] : 1 - f[1]) * (dz ? f[2] : 1 - f[2]);
    }
    return cell;
  }
  /// Trilinear at a cell of this grid (cellAt of this sampler or of one on the same grid).
  float operator()(const Cell& cell) const
  {
    double v = 0;
    for (int corner = 0; corner < 8; ++corner) {
      if (cell.weight[corner] == 0.0 && isBeyond(corner)) continue;
      const int dx = corner & 1, dy = (corner >> 1) & 1, dz = (corner >> 2) & 1;
      v += cell.weight[corner] * data_[cell.first + std::size_t(dx) + size_[0] * (std::size_t(dy) + size_[1] * std::size_t(dz))];
    }
    return float(v);
  }
  /// Trilinear; beyond the grid, the value at the nearest border voxel.
  float operator()(const double p[3]) const { return (*this)(cellAt(p)); }
  /// Whether `other` samples the same grid (the same cells for the same points).
  bool sameGrid(const DistanceSampler& other) const
  {
    return size_ == other.size_ && ImageGeometry::of(&image_).sameGridAs(ImageGeometry::of(&other.image_));
  }

private:
  bool isBeyond(int corner) const
  {
    const int dx = corner & 1, dy = (corner >> 1) & 1, dz = (corner >> 2) & 1;
    return (dx && size_[0] < 2) || (dy && size_[1] < 2) || (dz && size_[2] < 2);
  }
  const ScalarImage& image_;
  ScalarImage::SizeType size_;
  const float* data_;
  double inverse_[3][3], origin_[3];
};

std::vector<TissueDistance> tissueDistances(const LabelImage& labels, const std::vector<LabelPixel>& tissues)
{
  // One pass: the fraction of each tissue in bins of about 2 mm.
  const auto size = labels.GetLargestPossibleRegion().GetSize();
  unsigned factor[3];
  ScalarImage::SizeType coarseSize;
  ScalarImage::SpacingType coarseSpacing;
  for (int i = 0; i < 3; ++i) {
    factor[i] = std::max(1u, unsigned(std::lround(2.0 / labels.GetSpacing()[i])));
    coarseSize[i] = (size[i] + factor[i] - 1) / factor[i];
    coarseSpacing[i] = labels.GetSpacing()[i] * factor[i];
  }
  itk::ContinuousIndex<double, 3> firstBinCentre;
  for (int i = 0; i < 3; ++i) firstBinCentre[i] = 0.5 * (factor[i] - 1);
  ScalarImage::PointType coarseOrigin;
  labels.TransformContinuousIndexToPhysicalPoint(firstBinCentre, coarseOrigin);
  const std::size_t coarseCount = coarseSize[0] * coarseSize[1] * coarseSize[2];
  std::vector<std::vector<float>> fraction(tissues.size(), std::vector<float>(coarseCount, 0.f));
  std::vector<float> binVoxels(coarseCount, 0.f);
  std::map<LabelPixel, std::size_t> slot;
  for (std::size_t t = 0; t < tissues.size(); ++t) slot[tissues[t]] = t;
  const LabelPixel* l = labels.GetBufferPointer();
  for (std::size_t k = 0; k < size[2]; ++k) {
    for (std::size_t j = 0; j < size[1]; ++j) {
      for (std::size_t i = 0; i < size[0]; ++i) {
        const std::size_t bin = i / factor[0] + coarseSize[0] * (j / factor[1] + coarseSize[1] * (k / factor[2]));
        binVoxels[bin] += 1;
        auto s = slot.find(l[i + size[0] * (j + size[1] * k)]);
        if (s != slot.end()) fraction[s->second][bin] += 1;
      }
    }
  }
  std::vector<TissueDistance> result;
  for (std::size_t t = 0; t < tissues.size(); ++t) {
    auto mask = MaskImage::New();
    MaskImage::RegionType region;
    region.SetSize(coarseSize);
    mask->SetRegions(region);
    mask->SetSpacing(coarseSpacing);
    mask->SetOrigin(coarseOrigin);
    mask->SetDirection(labels.GetDirection());
    mask->Allocate();
    bool any = false;
    for (std::size_t b = 0; b < coarseCount; ++b) {
      mask->GetBufferPointer()[b] = fraction[t][b] >= 0.5f * binVoxels[b];
      any = any || mask->GetBufferPointer()[b];
    }
    if (!any) { // a thin tissue below half of every bin: keep the bins that hold the most of it
      float best = 0;
      for (std::size_t b = 0; b < coarseCount; ++b) best = std::max(best, fraction[t][b] / binVoxels[b]);
      for (std::size_t b = 0; b < coarseCount; ++b) mask->GetBufferPointer()[b] = best > 0 && fraction[t][b] / binVoxels[b] >= 0.5f * best;
    }
    TissueDistance td{tissues[t], signedDistanceMm(mask), 0.0};
    const float* d = td.distance->GetBufferPointer();
    td.deepestMm = -double(*std::min_element(d, d + coarseCount));
    result.push_back(td);
  }
  return result;
}

/// The intensity as one channel: 0 to 100 between the 1st and 99th percentile of the head.
std::vector<float> normalizedIntensity(const ScalarImage& image, const std::vector<unsigned char>& head, IntensityScale& scale)
{
  const float* v = image.GetBufferPointer();
  const std::size_t n = image.GetLargestPossibleRegion().GetNumberOfPixels();
  std::vector<float> values;
  values.reserve(n / 4);
  for (std::size_t i = 0; i < n; ++i) {
    if (head[i]) values.push_back(v[i]);
  }
  if (values.size() < 100) throw InputError("the intraoperative image shows no head where the aligned labels put it");
  auto percentile = [&](double q) {
    const std::size_t at = std::size_t(q * double(values.size() - 1));
    std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(at), values.end());
    return values[at];
  };
  scale.low = percentile(0.01);
  scale.high = percentile(0.99);
  std::vector<float> normalized(n);
  for (std::size_t i = 0; i < n; ++i) normalized[i] = scale.of(v[i]);
  return normalized;
}

ScalarImage::Pointer biasCorrected(const ScalarImage& image, const std::vector<unsigned char>& head)
{
  // N4 on a 4x shrunk image, the field then evaluated at full resolution.
  auto mask = MaskImage::New();
  mask->CopyInformation(&image);
  mask->SetRegions(image.GetLargestPossibleRegion());
  mask->Allocate();
  std::copy(head.begin(), head.end(), mask->GetBufferPointer());
  auto shrinkImage = itk::ShrinkImageFilter<ScalarImage, ScalarImage>::New();
  auto shrinkMask = itk::ShrinkImageFilter<MaskImage, MaskImage>::New();
  shrinkImage->SetInput(&image);
  shrinkMask->SetInput(mask);
  for (unsigned i = 0; i < 3; ++i) {
    const unsigned f = std::max(1u, unsigned(std::lround(4.0 / image.GetSpacing()[i])));
    shrinkImage->SetShrinkFactor(i, f);
    shrinkMask->SetShrinkFactor(i, f);
  }
  using N4 = itk::N4BiasFieldCorrectionImageFilter<ScalarImage, MaskImage, ScalarImage>;
  auto n4 = N4::New();
  n4->SetInput(shrinkImage->GetOutput());
  n4->SetMaskImage(shrinkMask->GetOutput());
  n4->SetMaskLabel(1);
  N4::VariableSizeArrayType iterations(3);
  iterations.Fill(30);
  n4->SetMaximumNumberOfIterations(iterations);
  n4->SetNumberOfFittingLevels(3);
  n4->Update();
  // Evaluate the fitted B-spline log field on the full grid.
  using LogField = itk::Image<N4::BiasFieldControlPointLatticeType::PixelType, 3>;
  auto reconstructer = itk::BSplineControlPointImageFilter<N4::BiasFieldControlPointLatticeType, LogField>::New();
  reconstructer->SetInput(n4->GetLogBiasFieldControlPointLattice());
  reconstructer->SetSplineOrder(n4->GetSplineOrder());
  reconstructer->SetSize(image.GetLargestPossibleRegion().GetSize());
  reconstructer->SetOrigin(image.GetOrigin());
  reconstructer->SetSpacing(image.GetSpacing());
  reconstructer->SetDirection(image.GetDirection());
  reconstructer->Update();
  auto corrected = ScalarImage::New();
  corrected->CopyInformation(&image);
  corrected->SetRegions(image.GetLargestPossibleRegion());
  corrected->Allocate();
  const std::size_t n = image.GetLargestPossibleRegion().GetNumberOfPixels();
  const auto* logField = reconstructer->GetOutput()->GetBufferPointer();
  for (std::size_t i = 0; i < n; ++i) corrected->GetBufferPointer()[i] = image.GetBufferPointer()[i] / std::exp(logField[i][0]);
  return corrected;
}

struct PrototypeCloud {
  std::vector<float> features;
  std::size_t dims = 0;
  std::size_t kdtree_get_point_count() const { return dims ? features.size() / dims : 0; }
  float kdtree_get_pt(std::size_t index, std::size_t dim) const { return features[index * dims + dim]; }
  template <class BoundingBox>
  bool kdtree_get_bbox(BoundingBox&) const { return false; }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PrototypeCloud>, PrototypeCloud, -1, std::size_t>;

/// Voxels with bit-identical features (most of the image: deep inside a tissue every distance is
/// 0 or saturated) share one k-NN answer. An open-addressing table per thread, keyed by the
/// feature bits, stores the voxel that was answered and its label.
class AnswerCache {
public:
  AnswerCache(const float* features, std::size_t dims)
    : features_(features), dims_(dims), slots_(std::size_t(1) << 20)
  {
  }
  /// The label of a voxel with the same features as `voxel`, or -1.
  int find(std::size_t voxel, std::uint64_t hash) const
  {
    for (std::size_t s = hash & mask(), probes = 0; probes < 64; s = (s + 1) & mask(), ++probes) {
      const Slot& slot = slots_[s];
      if (slot.label < 0) return -1;
      if (slot.hash == hash && std::memcmp(features_ + slot.voxel * dims_, features_ + voxel * dims_, dims_ * sizeof(float)) == 0) {
        return slot.label;
      }
    }
    return -1;
  }
  void insert(std::size_t voxel, std::uint64_t hash, LabelPixel label)
  {
    if (4 * (used_ + 1) > 3 * slots_.size()) return; // full enough: answer the rest directly
    for (std::size_t s = hash & mask();; s = (s + 1) & mask()) {
      if (slots_[s].label < 0) {
        slots_[s] = {hash, voxel, int(label)};
        ++used_;
        return;
      }
    }
  }
  static std::uint64_t hashOf(const float* f, std::size_t dims)
  {
    std::uint64_t h = 1469598103934665603ull; // FNV-1a over the bits
    for (std::size_t d = 0; d < dims; ++d) {
      std::uint32_t bits;
      std::memcpy(&bits, f + d, sizeof(bits));
      h = (h ^ bits) * 1099511628211ull;
    }
    return h ^ (h >> 29);
  }

private:
  struct Slot {
    std::uint64_t hash = 0;
    std::size_t voxel = 0;
    int label = -1;
  };
  std::size_t mask() const { return slots_.size() - 1; }
  const float* features_;
  std::size_t dims_;
  std::vector<Slot> slots_;
  std::size_t used_ = 0;
};

double median(std::vector<float> v)
{
  if (v.empty()) return std::nan("");
  std::nth_element(v.begin(), v.begin() + std::ptrdiff_t(v.size() / 2), v.end());
  return v[v.size() / 2];
}


} // namespace

ScanContrast scanContrastOf(const std::map<LabelPixel, std::vector<float>>& prototypeIntensity)
{
  auto medianOf = [&](LabelPixel label) {
    const auto found = prototypeIntensity.find(label);
    return found == prototypeIntensity.end() ? std::nan("") : median(found->second);
  };
  ScanContrast c;
  c.air = medianOf(Background);
  c.fluid = medianOf(Ventricles);
  c.parenchyma = medianOf(Parenchyma);
  return c;
}

bool ScanContrast::looksLikeFluidOrAir(double v) const
{
  if (!std::isfinite(parenchyma)) return false;
  const double toParenchyma = std::abs(v - parenchyma);
  return (std::isfinite(fluid) && std::abs(v - fluid) < toParenchyma) || (std::isfinite(air) && std::abs(v - air) < toParenchyma);
}

bool ScanContrast::fluidBrighterThanParenchyma() const
{
  return fluid > parenchyma;
}

namespace {

template <class TLabel>
itk::Image<unsigned, 3>::Pointer components(const MaskImage* mask, bool sortBySize)
{
  auto cc = itk::ConnectedComponentImageFilter<MaskImage, itk::Image<unsigned, 3>>::New();
  cc->SetInput(mask);
  cc->SetFullyConnected(false);
  if (!sortBySize) {
    cc->Update();
    return cc->GetOutput();
  }
  auto relabel = itk::RelabelComponentImageFilter<itk::Image<unsigned, 3>, itk::Image<unsigned, 3>>::New();
  relabel->SetInput(cc->GetOutput());
  relabel->Update();
  return relabel->GetOutput();
}

/// The tumour's place before surgery between the fluid (0) and the parenchyma (1); without it,
/// the parenchyma's.
double lookBeforeSurgery(const TumourResectionEvidence& e)
{
  return std::isfinite(e.preopRelative) ? e.preopRelative : 1.0;
}

/// A tumour that looked like the parenchyma before surgery (enhancing, isointense): within a
/// quarter of the way from it. Its voxels cannot be told from the tissue the rigid prior, or a sink,
/// put in its place.
bool lookedLikeParenchyma(const TumourResectionEvidence& e)
{
  return std::abs(1.0 - lookBeforeSurgery(e)) < 0.25;
}

} // namespace

/// Each of the tumour's intensities votes for what it looks like most: fluid, the tumour as it
/// looked before surgery (its place between fluid and parenchyma then; without it, the
/// parenchyma), or the parenchyma (tissue the rigid prior misplaced: no vote on the tumour). A
/// cavity holds fluid and air, whatever their order in this contrast (ScanContrast).
TumourResectionEvidence tumourResectionEvidenceOf(const std::vector<float>& tumourIntensities, const ScanContrast& contrast,
                                                  double preopRelative, TumourResection told)
{
  TumourResectionEvidence e;
  e.tumourMedian = median(tumourIntensities);
  e.parenchymaMedian = contrast.parenchyma;
  e.fluidMedian = contrast.fluid;
  e.airMedian = contrast.air;
  const double span = e.parenchymaMedian - e.fluidMedian;
  e.intraopRelative = std::abs(span) > 1e-6 ? (e.tumourMedian - e.fluidMedian) / span : std::nan("");
  e.preopRelative = preopRelative;
  e.decidedBy = told == TumourResection::Auto ? "image" : "user";
  e.voxels = tumourIntensities.size();
  if (std::isfinite(span) && std::abs(span) > 1e-6) {
    const double expected = e.fluidMedian + lookBeforeSurgery(e) * span;
    std::size_t fluid = 0, air = 0, tumour = 0, parenchyma = 0;
    for (float v : tumourIntensities) {
      // Air counts with the fluid (the cavity's upper part); in T1 it is nearer the fluid anyway.
      const double toLiquid = std::abs(v - e.fluidMedian);
      const double toAir = std::isfinite(e.airMedian) ? std::abs(v - e.airMedian) : std::numeric_limits<double>::infinity();
      const double toFluid = std::min(toLiquid, toAir);
      const double toTumour = std::abs(v - expected), toParenchyma = std::abs(v - e.parenchymaMedian);
      if (toFluid <= toTumour && toFluid <= toParenchyma) {
        ++fluid;
        air += toAir < toLiquid;
      } else if (toTumour <= toParenchyma) {
        ++tumour;
      } else {
        ++parenchyma;
      }
    }
    const double all = double(std::max<std::size_t>(1, fluid + tumour + parenchyma));
    e.fluidLikeShare = double(fluid) / all;
    e.airLikeShare = double(air) / all;
    e.tumourLikeShare = double(tumour) / all;
    e.parenchymaLikeShare = double(parenchyma) / all;
  }
  return e;
}

/// Resected when more of the tumour's prototypes look like fluid (or air) than like the tumour did
/// before surgery. A tumour that looked like fluid before surgery (within 0.15 of the way to the
/// parenchyma) cannot be told from its cavity by intensity: it is kept (the safe side: the
/// classification keeps it as tissue).
bool decideTumourResection(const TumourResectionEvidence& e, TumourResection told)
{
  if (told != TumourResection::Auto) return told == TumourResection::Resected;
  if (!std::isfinite(e.intraopRelative)) return false;
  const double before = lookBeforeSurgery(e);
  if (e.fluidMedian > e.parenchymaMedian) {
    // Fluid brighter than the parenchyma (T2): the tumour's look before surgery (a T1) does not
    // carry over (most tumours are bright in T2, as fluid is). Air, dark in every contrast and in
    // no tumour, is the cavity's sign (measured: 5-47 % of the prototypes of a resected tumour
    // under fluid and air, none of one in place); without it, most of the prototypes must look
    // like fluid, and a tumour that looked like fluid before surgery is kept.
    if (e.airLikeShare >= 0.03) return true;
    return before >= 0.15 && e.fluidLikeShare >= 0.5;
  }
  if (before < 0.15) return false;
  // A tumour that looked like the parenchyma: a cavity shows as fluid in a good share of it.
  if (lookedLikeParenchyma(e)) return e.fluidLikeShare >= 0.35;
  return e.fluidLikeShare > e.tumourLikeShare;
}

namespace {
/// A cavity under an open craniotomy holds air at its top; no tumour does (measured where the first
/// solve put the tumour, 144 runs of the scenarios: 8.4-16.8 % of a resected tumour, at most 2.2 %
/// of one in place).
constexpr double CavityAirShare = 0.05;
} // namespace

bool resectionShownWhereSolved(const TumourResectionEvidence& whereSolved)
{
  if (!(whereSolved.airLikeShare >= CavityAirShare) || !std::isfinite(whereSolved.intraopRelative)) return false;
  // A tumour that looked like the parenchyma cannot be told by intensity from the tissue that sank
  // into its place: its vote (the first look's 35 % of fluid) does not keep resected and intact
  // apart here (measured where the first solve put the tumour, 144 runs of the scenarios: 34-81 %
  // fluid-like in resected tumours, rf15-cavityrim 35-36 %, the small case 27.5 %; up to 34 % in
  // tumours left in place). The air does (8.4-16.8 % against at most 2.2 %), and decides alone.
  if (whereSolved.fluidMedian < whereSolved.parenchymaMedian && lookedLikeParenchyma(whereSolved)) return true;
  // A tumour with its own look must also look more like fluid than like itself: one beside the
  // gap's air is kept.
  return decideTumourResection(whereSolved, TumourResection::Auto);
}

bool tumourShownInPlaceWhereSolved(const TumourResectionEvidence& whereSolved)
{
  // Known air (a scan whose background gave prototypes), too little of it for a cavity, and hardly
  // any fluid: the vote alone lets a parenchyma-like tumour's place be up to 35 % fluid, as much as a
  // cavity shows where the solve put it (34-81 %, measured above), and a saline-filled cavity or a
  // dark gap has no air.
  constexpr double TissueFluidShare = 0.2;
  if (!std::isfinite(whereSolved.intraopRelative) || !std::isfinite(whereSolved.airMedian)) return false;
  if (!(whereSolved.airLikeShare < CavityAirShare) || !(whereSolved.fluidLikeShare < TissueFluidShare)) return false;
  return !decideTumourResection(whereSolved, TumourResection::Auto);
}

namespace {
/// A voxel nearer this scan's fluid or air than the tumour's own look before surgery (mapped onto
/// this scan's fluid and parenchyma), as the resection vote counts it. Never where that look does
/// not carry over (fluid brighter than the parenchyma: T2) or where the tumour looked like fluid
/// before surgery (within 0.15 of the way to the parenchyma): there its tissue cannot be told from
/// fluid, and it is kept.
bool tumourLooksLikeFluid(const TumourResectionEvidence& e, double intensity)
{
  const double span = e.parenchymaMedian - e.fluidMedian;
  if (!std::isfinite(span) || !(span > 1e-6) || !std::isfinite(e.preopRelative) || e.preopRelative < 0.15) return false;
  const double expected = e.fluidMedian + e.preopRelative * span;
  double toFluid = std::abs(intensity - e.fluidMedian);
  if (std::isfinite(e.airMedian)) toFluid = std::min(toFluid, std::abs(intensity - e.airMedian));
  return toFluid < std::abs(intensity - expected);
}

} // namespace

std::string toString(TumourResection decision)
{
  switch (decision) {
  case TumourResection::Auto: return "auto";
  case TumourResection::Resected: return "yes";
  case TumourResection::InPlace: return "no";
  }
  return "";
}

TumourResection tumourResectionFromString(const std::string& text)
{
  for (TumourResection d : {TumourResection::Auto, TumourResection::Resected, TumourResection::InPlace}) {
    if (toString(d) == text) return d;
  }
  throw InputError("--tumour-resected: '" + text + "' is not one of yes, no, auto");
}

TissueClassificationParameters classificationParametersFrom(const Configuration& configuration)
{
  TissueClassificationParameters parameters;
  parameters.k = configuration.classificationK;
  parameters.saturationMm = configuration.classificationSaturationMm;
  parameters.biasCorrection = configuration.classificationBiasCorrection;
  parameters.prototypesPerClass = std::max(configuration.classificationPrototypesPerTissue, parameters.k);
  parameters.seed = configuration.classificationSeed;
  parameters.tumourResection = tumourResectionFromString(configuration.classificationTumourResected);
  parameters.fluidThicknessInAlignedBrain = configuration.classificationFluidThicknessInAlignedBrain;
  parameters.tumourFluidByLook = configuration.classificationTumourFluidByLook;
  return parameters;
}

namespace {
/// The preoperative image's values over each brain tissue of the labels: voxel for voxel on one
/// grid; on another (the contract does not tie the labels to the image's grid) the image
/// interpolated at each label voxel's centre, those outside the image left out.
std::map<LabelPixel, std::vector<float>> preoperativeBrainIntensities(const ScalarImage& preopImage, const LabelImage& preopLabels)
{
  std::map<LabelPixel, std::vector<float>> values;
  const float* v = preopImage.GetBufferPointer();
  const LabelPixel* l = preopLabels.GetBufferPointer();
  const std::size_t n = preopLabels.GetLargestPossibleRegion().GetNumberOfPixels();
  const bool oneGrid = ImageGeometry::of(&preopImage).sameGridAs(ImageGeometry::of(&preopLabels));
  auto interpolator = itk::LinearInterpolateImageFunction<ScalarImage, double>::New();
  interpolator->SetInputImage(&preopImage);
  const auto size = preopLabels.GetLargestPossibleRegion().GetSize();
  for (std::size_t i = 0; i < n; ++i) {
    if (l[i] < Parenchyma || l[i] > Tumour) continue;
    if (oneGrid) {
      values[l[i]].push_back(v[i]);
      continue;
    }
    PhysicalPoint x;
    preopLabels.TransformIndexToPhysicalPoint({{itk::IndexValueType(i % size[0]), itk::IndexValueType((i / size[0]) % size[1]),
                                                itk::IndexValueType(i / (size[0] * size[1]))}},
                                              x);
    if (interpolator->IsInsideBuffer(x)) values[l[i]].push_back(float(interpolator->Evaluate(x)));
  }
  return values;
}

/// The tumour's place between the fluid (0) and the parenchyma (1), from the tissues' values.
double tumourContrastOf(std::map<LabelPixel, std::vector<float>>& values)
{
  if (values[Tumour].empty() || values[Ventricles].empty() || values[Parenchyma].empty()) return std::nan("");
  const double fluid = median(values[Ventricles]), parenchyma = median(values[Parenchyma]);
  if (std::abs(parenchyma - fluid) < 1e-6) return std::nan("");
  return (median(values[Tumour]) - fluid) / (parenchyma - fluid);
}
} // namespace

void takePreoperativeImage(TissueClassificationParameters& parameters, const ScalarImage& preopImage,
                           const LabelImage& preopLabels, const SpatialTransform& intraopToPreop)
{
  auto values = preoperativeBrainIntensities(preopImage, preopLabels); // once for both
  parameters.preopTumourContrast = tumourContrastOf(values);
  parameters.preopLook = PreoperativeImageLook{&preopImage, &intraopToPreop, {median(values[Ventricles]), median(values[Parenchyma])}};
}

double preoperativeTumourContrast(const ScalarImage& preopImage, const LabelImage& preopLabels)
{
  auto values = preoperativeBrainIntensities(preopImage, preopLabels);
  return tumourContrastOf(values);
}

std::string tissueName(LabelPixel label)
{
  switch (label) {
  case Background: return "background";
  case Head: return "head";
  case Parenchyma: return "parenchyma";
  case Ventricles: return "ventricles";
  case Tumour: return "tumour";
  default: return std::to_string(label);
  }
}

void TissueClassificationParameters::validate() const
{
  if (k == 0 || k > 101) throw InputError("classification: k = " + std::to_string(k) + " is outside 1 to 101");
  if (!(saturationMm > 0 && saturationMm <= 100)) throw InputError("classification: saturation distance must be within 0 to 100 mm");
  if (!(intensityWeight >= 0) || !(spatialWeight >= 0) || intensityWeight + spatialWeight == 0) {
    throw InputError("classification: channel weights must be non-negative and not both zero");
  }
  if (prototypesPerClass < k) {
    throw InputError("classification: " + std::to_string(prototypesPerClass) + " prototypes per class is fewer than k = " + std::to_string(k));
  }
  if (!(prototypeErosionMm >= 0) || !(fluidOpeningMm >= 0) || !(smallHoleMl >= 0) || !(gapReachMm >= 0) || !(cavityReachMm >= 0)) {
    throw InputError("classification: erosion, opening, gap and cavity reach and hole size must be non-negative");
  }
}

class PreoperativeTissueMaps {
public:
  const LabelImage* labels = nullptr;      ///< prepared from (identity, not ownership)
  const LabelPixel* voxels = nullptr;      ///< and its buffer then
  std::set<LabelPixel> present;
  std::vector<LabelPixel> tissues;         ///< present, in order
  std::vector<TissueDistance> distances;   ///< one per tissue
};

std::shared_ptr<const PreoperativeTissueMaps> preparePreoperativeTissueMaps(const LabelImage& preopLabels)
{
  auto maps = std::make_shared<PreoperativeTissueMaps>();
  maps->labels = &preopLabels;
  maps->voxels = preopLabels.GetBufferPointer();
  const LabelPixel* l = preopLabels.GetBufferPointer();
  for (std::size_t i = 0, n = preopLabels.GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) maps->present.insert(l[i]);
  for (LabelPixel required : {Background, Parenchyma}) {
    if (!maps->present.count(required)) {
      throw InputError("classification: the preoperative labels have no " + tissueName(required) + " (label " +
                       std::to_string(required) + ")");
    }
  }
  maps->tissues.assign(maps->present.begin(), maps->present.end());
  maps->distances = tissueDistances(preopLabels, maps->tissues);
  return maps;
}

namespace {

/// What the steps of one classification share: the scan, the parameters, the preoperative tissues
/// and, as the steps fill them, the saturated distances to each tissue on the intraoperative grid,
/// the head, the intensity channel, the features and the prototypes.
/// An allocator whose vectors leave new elements uninitialised: the per-voxel tables below are
/// written whole by loops on both cores, and zeroing them first (80-95 MB, on one core, on pages
/// the kernel must clear anyway) only delayed those loops (the first scan's features 0.59-0.70 ->
/// 0.49-0.52 s on the full built-in case; the labels the same).
template <class T>
struct LeftUninitialised : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = LeftUninitialised<U>;
  };
  LeftUninitialised() = default;
  template <class U>
  LeftUninitialised(const LeftUninitialised<U>&) noexcept
  {
  }
  template <class U>
  void construct(U* p) noexcept
  {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args)
  {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};
using VoxelTable = std::vector<float, LeftUninitialised<float>>;

struct ClassificationWork {
  ClassificationWork(const ScalarImage& scan, const TissueClassificationParameters& parameters,
                     std::shared_ptr<const PreoperativeTissueMaps> tissueMaps)
    : intraop(scan)
    , P(parameters)
    , size(scan.GetLargestPossibleRegion().GetSize())
    , N(scan.GetLargestPossibleRegion().GetNumberOfPixels())
    , maps(std::move(tissueMaps))
    , T(maps->tissues.size())
    , D(1 + T) // intensity, then one distance per tissue
  {
  }
  const ScalarImage& intraop;
  const TissueClassificationParameters& P;
  const itk::Size<3> size;
  const std::size_t N;
  const std::shared_ptr<const PreoperativeTissueMaps> maps;
  const std::size_t T, D;
  VoxelTable signedDistances;         ///< N x T, saturated at P.saturationMm
  std::vector<unsigned char> head;    ///< not background in the aligned labels
  std::vector<float> intensity;       ///< 0-100 over the head
  IntensityScale intensityScale;      ///< of `intensity`
  VoxelTable features;                ///< N x D
  std::vector<std::size_t> prototypeVoxels;
  std::vector<LabelPixel> prototypeLabels;

  std::size_t slotOf(LabelPixel label) const
  {
    return std::size_t(std::find(maps->tissues.begin(), maps->tissues.end(), label) - maps->tissues.begin());
  }
  float distance(std::size_t voxel, std::size_t slot) const { return signedDistances[voxel * T + slot]; }
};

/// The tissue maps given with the parameters (checked to be of these labels), else prepared here.
std::shared_ptr<const PreoperativeTissueMaps> tissueMapsFor(const LabelImage& preopLabels, const TissueClassificationParameters& P)
{
  if (!P.preoperativeMaps) return preparePreoperativeTissueMaps(preopLabels);
  if (P.preoperativeMaps->labels != &preopLabels || P.preoperativeMaps->voxels != preopLabels.GetBufferPointer()) {
    throw std::invalid_argument("classification: the preoperative tissue maps were prepared from other labels");
  }
  return P.preoperativeMaps;
}

/// The saturated signed distance to each preoperative tissue at every intraoperative voxel (where
/// the rigid transform puts it in the preoperative frame: x = A (origin + M index) + t), and the head.
void sampleAlignedDistances(ClassificationWork& w, const SpatialTransform& rigid)
{
  const AffineParameters rigidParameters = affineParametersOf(&rigid);
  const GridMap grid(w.intraop);
  double A[3][3], b[3];
  for (int r = 0; r < 3; ++r) {
    b[r] = rigidParameters.translation[r];
    for (int c = 0; c < 3; ++c) {
      A[r][c] = 0;
      for (int k = 0; k < 3; ++k) A[r][c] += rigidParameters.matrix[r][k] * grid.m[k][c];
      b[r] += rigidParameters.matrix[r][c] * grid.origin[c];
    }
  }
  std::vector<DistanceSampler> samplers;
  for (const auto& d : w.maps->distances) samplers.emplace_back(*d.distance);
  const auto size = w.size;
  const std::size_t T = w.T;
  w.signedDistances.resize(w.N * T); // every element written below
  w.head.assign(w.N, 0);
  const std::size_t backgroundSlot = 0; // tissues are sorted; 0 is background
  // The maps share one grid (preparePreoperativeTissueMaps): a voxel's cell is found once.
  bool oneGrid = !samplers.empty();
  for (const DistanceSampler& sampler : samplers) oneGrid = oneGrid && sampler.sameGrid(samplers.front());
  parallelRanges(w.N, [&](std::size_t begin, std::size_t end, unsigned) {
    double x[3];
    for (std::size_t i = begin; i < end; ++i) {
      const double ii = double(i % size[0]), j = double((i / size[0]) % size[1]), k = double(i / (size[0] * size[1]));
      for (int r = 0; r < 3; ++r) x[r] = b[r] + A[r][0] * ii + A[r][1] * j + A[r][2] * k;
      const DistanceSampler::Cell cell = oneGrid ? samplers.front().cellAt(x) : DistanceSampler::Cell{};
      for (std::size_t t = 0; t < T; ++t) {
        const float d = oneGrid ? samplers[t](cell) : samplers[t](x);
        w.signedDistances[i * T + t] = std::clamp(d, float(-w.P.saturationMm), float(w.P.saturationMm));
      }
      w.head[i] = w.signedDistances[i * T + backgroundSlot] > 0.0f;
    }
  });
}

/// The intensity channel (after N4 when asked) and the features. Features on fixed steps: the
/// intensity to 0.1 of its 0-100 scale (a 12-bit scanner's resolution, far below the noise), the
/// distances to 0.25 mm (the maps have 2 mm bins). Voxels then share features, and answers
/// (AnswerCache): on the built-in case 83 % fewer k-NN queries (301,138 against 1,759,889) for the
/// same labels (brain Dice against the truth 0.9810 both).
void computeFeatures(ClassificationWork& w)
{
  ScalarImage::Pointer corrected;
  const ScalarImage* source = &w.intraop;
  if (w.P.biasCorrection) {
    corrected = biasCorrected(w.intraop, w.head);
    source = corrected;
  }
  w.intensity = normalizedIntensity(*source, w.head, w.intensityScale);
  const std::size_t T = w.T, D = w.D;
  w.features.resize(w.N * D); // every element written below
  parallelRanges(w.N, [&](std::size_t begin, std::size_t end, unsigned) {
    for (std::size_t i = begin; i < end; ++i) {
      w.features[i * D] = float(w.P.intensityWeight) * (std::round(w.intensity[i] * 10.0f) / 10.0f);
      for (std::size_t t = 0; t < T; ++t) {
        const float distance = std::round(std::max(0.0f, w.signedDistances[i * T + t]) * 4.0f) / 4.0f;
        w.features[i * D + 1 + t] = float(w.P.spatialWeight) * distance;
      }
    }
  });
}

/// The prototypes a user gave (positions on the intraoperative grid), at least k of each tissue.
void takeGivenPrototypes(ClassificationWork& w, const std::vector<TissuePrototype>& given, TissueClassificationResult& result)
{
  std::map<LabelPixel, unsigned> counts;
  for (const TissuePrototype& p : given) {
    itk::Index<3> index;
    if (!w.intraop.TransformPhysicalPointToIndex(p.position, index)) {
      std::ostringstream message;
      message << "classification: prototype '" << p.name << "' at (" << p.position[0] << ", " << p.position[1] << ", "
              << p.position[2] << ") is outside the intraoperative image";
      throw InputError(message.str());
    }
    if (!w.maps->present.count(p.label)) {
      throw InputError("classification: prototype '" + p.name + "' is " + tissueName(p.label) +
                       ", a label the preoperative labels do not have");
    }
    w.prototypeVoxels.push_back(index[0] + w.size[0] * (index[1] + w.size[1] * index[2]));
    w.prototypeLabels.push_back(p.label);
    counts[p.label] += 1;
    result.prototypes.push_back(p);
  }
  for (LabelPixel label : w.maps->tissues) {
    if (counts[label] < w.P.k) {
      throw InputError("classification: " + std::to_string(counts[label]) + " prototypes of " + tissueName(label) + " (label " +
                       std::to_string(label) + "); k = " + std::to_string(w.P.k) + " needs at least as many");
    }
  }
}

/// The grid's voxels in the order of the patient's axes: right to left fastest, then anterior to
/// posterior, then inferior to superior (LPS ascending), whatever the order and sense in which the
/// scan stores them: the same head acquired sagittally, coronally or flipped gives the same
/// sequence of physical voxels, so the seeded choice of prototypes picks the same voxels. Empty
/// when that is the storage order already (an axial grid along LPS), or when the grid's axes are
/// too oblique to be matched one for one with the patient's (then the storage order is kept).
std::vector<std::size_t> patientAxisOrder(const ScalarImage& grid)
{
  const auto direction = grid.GetDirection();
  std::array<int, 3> gridAxisOf{-1, -1, -1}; // per patient axis
  std::array<bool, 3> ascending{};
  for (int a = 0; a < 3; ++a) {
    int along = 0;
    for (int p = 1; p < 3; ++p) {
      if (std::abs(direction(p, a)) > std::abs(direction(along, a))) along = p;
    }
    if (std::abs(direction(along, a)) <= std::sqrt(0.5) + 1e-9 || gridAxisOf[std::size_t(along)] >= 0) return {};
    gridAxisOf[std::size_t(along)] = a;
    ascending[std::size_t(along)] = direction(along, a) > 0;
  }
  if (gridAxisOf == std::array<int, 3>{0, 1, 2} && ascending[0] && ascending[1] && ascending[2]) return {};
  const auto size = grid.GetLargestPossibleRegion().GetSize();
  const std::size_t strides[3] = {1, size[0], size[0] * size[1]};
  auto step = [&](int patientAxis, std::size_t c) {
    const int a = gridAxisOf[std::size_t(patientAxis)];
    const std::size_t n = size[std::size_t(a)];
    return (ascending[std::size_t(patientAxis)] ? c : n - 1 - c) * strides[a];
  };
  std::vector<std::size_t> order;
  order.reserve(grid.GetLargestPossibleRegion().GetNumberOfPixels());
  for (std::size_t s = 0; s < size[std::size_t(gridAxisOf[2])]; ++s) {
    for (std::size_t a = 0; a < size[std::size_t(gridAxisOf[1])]; ++a) {
      const std::size_t slowPart = step(2, s) + step(1, a);
      for (std::size_t l = 0; l < size[std::size_t(gridAxisOf[0])]; ++l) order.push_back(slowPart + step(0, l));
    }
  }
  return order;
}

/// Candidate voxels for the prototypes of tissue slot `t`: inside the aligned tissue by the
/// erosion (or half its depth for thin tissues); on coarse grids, less deep until there are enough;
/// for a tissue thinner than the voxels, its most interior voxels, up to 1 mm out (with a warning).
/// Each as its place in `order` (patientAxisOrder; empty: the storage order) and its voxel.
struct PrototypeCandidate {
  std::size_t place, voxel;
};
std::vector<PrototypeCandidate> prototypeCandidates(const ClassificationWork& w, std::size_t t, const std::vector<std::size_t>& order,
                                                    TissueClassificationResult& result)
{
  auto voxel = [&order](std::size_t n) { return order.empty() ? n : order[n]; };
  std::vector<PrototypeCandidate> candidates;
  for (double erosion = std::min(w.P.prototypeErosionMm, 0.5 * w.maps->distances[t].deepestMm);; erosion *= 0.5) {
    if (erosion < 0.25) erosion = 0.0;
    candidates.clear();
    for (std::size_t n = 0; n < w.N; ++n) {
      const std::size_t i = voxel(n);
      if (w.distance(i, t) <= -erosion && (erosion > 0 || w.distance(i, t) < 0)) candidates.push_back({n, i});
    }
    if (candidates.size() >= 2 * w.P.prototypesPerClass || erosion == 0.0) break;
  }
  if (candidates.size() < 3 * std::size_t(w.P.k)) {
    candidates.clear();
    std::vector<std::pair<float, std::size_t>> nearest; // distance, place in `order`
    for (std::size_t n = 0; n < w.N; ++n) {
      if (w.distance(voxel(n), t) < 1.0f) nearest.emplace_back(w.distance(voxel(n), t), n);
    }
    const std::size_t want = std::min<std::size_t>(nearest.size(), 4 * std::size_t(w.P.k));
    std::partial_sort(nearest.begin(), nearest.begin() + std::ptrdiff_t(want), nearest.end());
    for (std::size_t n = 0; n < want; ++n) candidates.push_back({nearest[n].second, voxel(nearest[n].second)});
    result.warnings.push_back("classify: " + tissueName(w.maps->tissues[t]) + " is thinner than the intraoperative voxels; " +
                              std::to_string(candidates.size()) + " prototypes from its most interior voxels");
  }
  return candidates;
}

/// SplitMix64's finaliser: 64 well-mixed bits from any 64.
std::uint64_t mixed(std::uint64_t x)
{
  x += 0x9e3779b97f4a7c15ull;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

/// The candidates drawn for the prototypes of tissue slot `t`: the 4 P.prototypesPerClass whose
/// keys are smallest, in the order of their keys, a key a hash of the seed, the tissue and the
/// voxel's place in the patient's order (a bottom-k sample: as random as a shuffle, but each
/// voxel's key its own). A candidate set that gains or loses a few voxels (a prior a fraction of a
/// millimetre elsewhere, a refine pass's warped labels from a field a little different) changes
/// the draw by those few; a shuffle of the list redrew all of it, and of every tissue after it,
/// whose shuffles took the generator on from there: rf10-t2-intact's update moved from 0.89 to
/// 1.59 mm at the boundary on a prior 976 voxels different.
std::vector<std::size_t> drawnCandidates(const ClassificationWork& w, std::size_t t, const std::vector<PrototypeCandidate>& candidates)
{
  const std::uint64_t tissueSeed = mixed(mixed(w.P.seed) ^ std::uint64_t(w.maps->tissues[t]));
  std::vector<std::pair<std::uint64_t, std::size_t>> keyed;
  keyed.reserve(candidates.size());
  for (const PrototypeCandidate& c : candidates) keyed.emplace_back(mixed(tissueSeed ^ std::uint64_t(c.place)), c.voxel);
  const std::size_t take = std::min<std::size_t>(keyed.size(), 4 * w.P.prototypesPerClass);
  if (take < keyed.size()) {
    std::nth_element(keyed.begin(), keyed.begin() + std::ptrdiff_t(take), keyed.end());
    keyed.resize(take);
  }
  std::sort(keyed.begin(), keyed.end());
  std::vector<std::size_t> drawn;
  drawn.reserve(take);
  for (const auto& [key, voxel] : keyed) drawn.push_back(voxel);
  return drawn;
}

/// Up to P.prototypesPerClass of the drawn candidates, leaving out intensity outliers (more than 3
/// robust spreads from their median): what the rigid prior cannot know (tissue that moved).
void keepTypicalCandidates(ClassificationWork& w, std::size_t t, const std::vector<PrototypeCandidate>& all)
{
  const std::vector<std::size_t> candidates = drawnCandidates(w, t, all);
  std::vector<float> values;
  for (std::size_t i : candidates) values.push_back(w.intensity[i]);
  const double m = median(values);
  std::vector<float> deviations;
  for (float v : values) deviations.push_back(float(std::abs(v - m)));
  const double spread = std::max(1.0, 1.4826 * median(deviations));
  unsigned kept = 0;
  for (std::size_t i : candidates) {
    if (kept == w.P.prototypesPerClass) break;
    if (std::abs(w.intensity[i] - m) > 3.0 * spread) continue;
    w.prototypeVoxels.push_back(i);
    w.prototypeLabels.push_back(w.maps->tissues[t]);
    ++kept;
  }
  if (kept < w.P.k) {
    throw InputError("classification: only " + std::to_string(kept) + " prototypes of " + tissueName(w.maps->tissues[t]) +
                     " could be chosen (the tissue is too small after aligning); k = " + std::to_string(w.P.k));
  }
}

/// Prototypes chosen from the aligned preoperative tissues (seeded), recorded with names and
/// positions for the next scan.
void choosePrototypes(ClassificationWork& w, TissueClassificationResult& result)
{
  const std::vector<std::size_t> order = patientAxisOrder(w.intraop);
  for (std::size_t t = 0; t < w.T; ++t) keepTypicalCandidates(w, t, prototypeCandidates(w, t, order, result));
  for (std::size_t p = 0; p < w.prototypeVoxels.size(); ++p) {
    const std::size_t i = w.prototypeVoxels[p];
    itk::Index<3> index{{itk::IndexValueType(i % w.size[0]), itk::IndexValueType((i / w.size[0]) % w.size[1]),
                         itk::IndexValueType(i / (w.size[0] * w.size[1]))}};
    TissuePrototype prototype;
    prototype.label = w.prototypeLabels[p];
    prototype.name = tissueName(prototype.label) + "-" + std::to_string(p + 1);
    w.intraop.TransformIndexToPhysicalPoint(index, prototype.position);
    result.prototypes.push_back(prototype);
  }
}

/// What the prototypes say of this scan: its contrast (every intensity rule below is stated
/// through these medians) and whether the tumour was resected (decideTumourResection); then the
/// prototypes the k-NN uses (a resected tumour's class dropped: where it was, fluid is decided by
/// the clean-up).
PrototypeCloud learnFromPrototypes(const ClassificationWork& w, TissueClassificationResult& result, std::vector<LabelPixel>& cloudLabels)
{
  std::map<LabelPixel, std::vector<float>> prototypeIntensity;
  for (std::size_t p = 0; p < w.prototypeVoxels.size(); ++p) {
    prototypeIntensity[w.prototypeLabels[p]].push_back(w.intensity[w.prototypeVoxels[p]]);
  }
  result.contrast = scanContrastOf(prototypeIntensity);
  if (!w.maps->present.count(Ventricles)) result.contrast.fluid = std::nan("");
  if (w.maps->present.count(Tumour)) {
    result.tumourEvidence = tumourResectionEvidenceOf(prototypeIntensity[Tumour], result.contrast, w.P.preopTumourContrast, w.P.tumourResection);
    result.tumourResected = decideTumourResection(result.tumourEvidence, w.P.tumourResection);
  }
  PrototypeCloud cloud;
  cloud.dims = w.D;
  for (std::size_t p = 0; p < w.prototypeVoxels.size(); ++p) {
    if (result.tumourResected && w.prototypeLabels[p] == Tumour) continue;
    cloud.features.insert(cloud.features.end(), w.features.begin() + std::ptrdiff_t(w.prototypeVoxels[p] * w.D),
                          w.features.begin() + std::ptrdiff_t((w.prototypeVoxels[p] + 1) * w.D));
    cloudLabels.push_back(w.prototypeLabels[p]);
    result.prototypesPerClass[w.prototypeLabels[p]] += 1;
  }
  return cloud;
}

/// Exact k-NN (kd-tree) of every voxel among the prototypes, voxels with bit-identical features
/// answered once; majority vote, a tie to the class of the nearest prototype among the tied.
void labelByNearestPrototypes(const ClassificationWork& w, PrototypeCloud& cloud, const std::vector<LabelPixel>& cloudLabels,
                              TissueClassificationResult& result)
{
  throwIfCancelled(w.P.cancel, "tissue classification");
  const std::size_t D = w.D;
  KdTree tree(D, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(12));
  tree.buildIndex();
  result.labels = LabelImage::New();
  result.labels->CopyInformation(&w.intraop);
  result.labels->SetRegions(w.intraop.GetLargestPossibleRegion());
  result.labels->Allocate();
  LabelPixel* out = result.labels->GetBufferPointer();
  const unsigned k = w.P.k;
  std::vector<std::size_t> queriesPerThread(16, 0);
  parallelRanges(w.N, [&](std::size_t begin, std::size_t end, unsigned thread) {
    AnswerCache cache(w.features.data(), D);
    std::vector<std::size_t> neighbours(k);
    std::vector<float> squaredDistances(k);
    std::map<LabelPixel, unsigned> tally;
    std::size_t queries = 0;
    for (std::size_t i = begin; i < end; ++i) {
      if ((i & 0xffff) == 0 && w.P.cancel && w.P.cancel->load(std::memory_order_relaxed)) break; // thrown below
      const float* f = &w.features[i * D];
      const std::uint64_t hash = AnswerCache::hashOf(f, D);
      const int known = cache.find(i, hash);
      if (known >= 0) {
        out[i] = LabelPixel(known);
        continue;
      }
      ++queries;
      nanoflann::KNNResultSet<float, std::size_t> found(k);
      found.init(neighbours.data(), squaredDistances.data());
      tree.findNeighbors(found, f, nanoflann::SearchParams(32, 0.0f, true));
      tally.clear();
      unsigned best = 0;
      for (std::size_t n = 0; n < found.size(); ++n) best = std::max(best, ++tally[cloudLabels[neighbours[n]]]);
      LabelPixel chosen = cloudLabels[neighbours[0]];
      for (std::size_t n = 0; n < found.size(); ++n) {
        if (tally[cloudLabels[neighbours[n]]] == best) {
          chosen = cloudLabels[neighbours[n]];
          break;
        }
      }
      out[i] = chosen;
      cache.insert(i, hash, chosen);
    }
    queriesPerThread[thread] = queries;
  });
  throwIfCancelled(w.P.cancel, "tissue classification");
  for (std::size_t q : queriesPerThread) result.knnQueries += q;
}

bool isBrainLabel(LabelPixel l)
{
  return l == Parenchyma || l == Ventricles || l == Tumour;
}

MaskImage::Pointer maskOnGrid(const ScalarImage& grid)
{
  auto mask = MaskImage::New();
  mask->CopyInformation(&grid);
  mask->SetRegions(grid.GetLargestPossibleRegion());
  mask->Allocate();
  return mask;
}

/// Fluid (or air) in the brain: what looks more like this scan's fluid or background than like its
/// parenchyma (in T1, darker than halfway from the fluid to the parenchyma, as it always was; in
/// T2 the bright fluid and the dark air both).
///
/// A tumour that is still there is tissue, however dark its core: what the k-NN calls tumour
/// stays out of the fluid unless it looks more like fluid or air than the tumour did before
/// surgery (tumourLooksLikeFluid): the fluid of a gap or a cavity the k-NN gave to a tumour
/// wrongly kept (its cavity moved away from the rigid prior) is fluid.
///
/// Its thickness is measured over what the k-NN or the aligned preoperative brain calls brain:
/// the gap the brain sank away from lies inside the aligned brain, and the k-NN gives its
/// shallow part (within the spatial channels' saturation of the aligned surface) to the head,
/// so the brain-labelled rest of it is a sheet too thin to count as thick, and stays brain.
/// Not where the fluid is brighter than the parenchyma (T2): there what the k-NN gives to the
/// head inside the aligned brain is mostly bright cortex (partial volume with its CSF), and
/// counted as fluid it made thick bodies of the cortex (rf10-t2: 16 ml of parenchyma lost).
MaskImage::Pointer fluidInBrain(const ClassificationWork& w, const TissueClassificationResult& result, const LabelPixel* out)
{
  const ScanContrast& contrast = result.contrast;
  MaskImage::Pointer fluid = maskOnGrid(w.intraop);
  const bool tumourPresent = w.maps->present.count(Tumour) && !result.tumourResected;
  const TumourResectionEvidence& evidence = result.tumourEvidence;
  const bool alignedBrainToo = w.P.fluidThicknessInAlignedBrain && !contrast.fluidBrighterThanParenchyma();
  const std::vector<std::size_t> brainSlots = {w.slotOf(Parenchyma), w.slotOf(Ventricles), w.slotOf(Tumour)};
  auto inAlignedBrain = [&](std::size_t i) {
    for (std::size_t slot : brainSlots) {
      if (slot < w.T && w.distance(i, slot) <= 0.0f) return true;
    }
    return false;
  };
  for (std::size_t i = 0; i < w.N; ++i) {
    const bool candidate = isBrainLabel(out[i]) || (alignedBrainToo && inAlignedBrain(i));
    const bool tumourTissue = tumourPresent && out[i] == Tumour &&
                              !(w.P.tumourFluidByLook && tumourLooksLikeFluid(evidence, w.intensity[i]));
    fluid->GetBufferPointer()[i] = candidate && contrast.looksLikeFluidOrAir(w.intensity[i]) && !tumourTissue;
  }
  return fluid;
}

/// The part of `fluid` thicker than P.fluidOpeningMm: a morphological opening (the voxels that
/// deep, then the fluid within that reach of them: the distance maps' tests, without the maps).
/// The reach back is at least one voxel along every axis (an ellipsoid of semi-axes
/// max(opening, spacing)): depth is measured to the centres of the fluid's boundary voxels, so on
/// 2.5 mm slices the slice next to the core lies 2.5 mm from it, and a 2 mm reach left the fluid's
/// boundary slices out of a body however thick it was.
MaskImage::Pointer thickPartOf(const ClassificationWork& w, const MaskImage::Pointer& fluid)
{
  const double opening = w.P.fluidOpeningMm;
  const MaskImage::Pointer core = voxelsAtLeastDeep(fluid, opening);
  // The ellipsoid as a ball of radius `opening` on a grid whose spacing is scaled per axis.
  MaskImage::SpacingType scaled = core->GetSpacing();
  for (unsigned a = 0; a < 3; ++a) scaled[a] *= opening > 0 ? opening / std::max(opening, scaled[a]) : 1.0;
  core->SetSpacing(scaled);
  MaskImage::Pointer thick = voxelsWithin(core, opening + 1e-3);
  thick->CopyInformation(fluid);
  for (std::size_t i = 0; i < w.N; ++i) thick->GetBufferPointer()[i] = thick->GetBufferPointer()[i] && fluid->GetBufferPointer()[i];
  return thick;
}

/// Whether the preoperative image (P.preopLook, through its transform, linear interpolation)
/// showed tissue at an intraoperative voxel: a value nearer the preoperative parenchyma's median than
/// the ventricles'. False outside the preoperative image.
class PreoperativeTissueLook {
public:
  PreoperativeTissueLook(const ClassificationWork& w, const PreoperativeImageLook& look)
    : w_(w)
    , transform_(*look.intraopToPreop)
    , middle_(0.5 * (look.medians.fluid + look.medians.parenchyma))
    , tissueBrighter_(look.medians.parenchyma > look.medians.fluid)
    , interpolator_(itk::LinearInterpolateImageFunction<ScalarImage, double>::New())
  {
    interpolator_->SetInputImage(look.image);
  }
  bool operator()(std::size_t voxel) const
  {
    const auto size = w_.size;
    const itk::Index<3> index = {{itk::IndexValueType(voxel % size[0]), itk::IndexValueType((voxel / size[0]) % size[1]),
                                  itk::IndexValueType(voxel / (size[0] * size[1]))}};
    PhysicalPoint x;
    w_.intraop.TransformIndexToPhysicalPoint(index, x);
    const PhysicalPoint before = transform_.TransformPoint(x);
    if (!interpolator_->IsInsideBuffer(before)) return false;
    const double value = interpolator_->Evaluate(before);
    return tissueBrighter_ ? value > middle_ : value < middle_;
  }

private:
  const ClassificationWork& w_;
  const SpatialTransform& transform_;
  const double middle_;
  const bool tissueBrighter_;
  itk::LinearInterpolateImageFunction<ScalarImage, double>::Pointer interpolator_;
};

/// The gaps and cavities take the fluid they reach through fluid: from their voxels (`gaps`), over
/// face neighbours, the `fluid` the k-NN calls parenchyma or tumour (not ventricles: moved, they lie
/// where tissue was) within P.gapReachMm of path (at least one voxel step along every axis, so a
/// 2.5 mm slice can be crossed; P.cavityReachMm where the spatial prior's tumour is within
/// P.saturationMm and `tumourResected`), where the preoperative image showed tissue.
/// That is the sheet of fluid pooled over a brain that sank (brain before it sank); sulci and
/// cisterns next to a gap were fluid before surgery too and stay brain. Returns the voxels taken.
std::size_t joinFluidToGaps(const ClassificationWork& w, const MaskImage& fluid, const std::vector<std::size_t>& gaps, bool tumourResected,
                            LabelPixel* out)
{
  const PreoperativeImageLook& look = *w.P.preopLook;
  if (gaps.empty() || !look.image || !look.intraopToPreop || !std::isfinite(look.medians.fluid) ||
      !std::isfinite(look.medians.parenchyma) || look.medians.fluid == look.medians.parenchyma) {
    return 0;
  }
  const PreoperativeTissueLook showedTissue(w, look);
  const auto spacing = w.intraop.GetSpacing();
  const float reach = float(std::max({w.P.gapReachMm, spacing[0], spacing[1], spacing[2]}) + 1e-3);
  // Around a resection cavity (within the spatial channels' saturation of the prior's tumour) the
  // reach is the cavity's: the cavity and the gap are one body of fluid, and a long reach from the
  // cavity takes the tissue around it.
  const float cavityReach = float(std::max({w.P.cavityReachMm, spacing[0], spacing[1], spacing[2]}) + 1e-3);
  const std::size_t tumourSlot = w.slotOf(Tumour);
  const bool cavity = tumourResected && tumourSlot < w.T;
  auto reachAt = [&](std::size_t voxel) {
    return cavity && w.distance(voxel, tumourSlot) < float(w.P.saturationMm) ? std::min(cavityReach, reach) : reach;
  };
  const auto size = w.size;
  const std::size_t strides[3] = {1, size[0], size[0] * size[1]};
  const unsigned char* isFluid = fluid.GetBufferPointer();
  constexpr float unreached = std::numeric_limits<float>::infinity();
  std::vector<float> pathMm(w.N, unreached);
  using Entry = std::pair<float, std::size_t>;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<Entry>> front;
  for (std::size_t i : gaps) {
    pathMm[i] = 0.0f;
    front.push({0.0f, i});
  }
  std::size_t joined = 0;
  while (!front.empty()) {
    const auto [path, i] = front.top();
    front.pop();
    if (path > pathMm[i]) continue;
    const std::size_t at[3] = {i % size[0], (i / size[0]) % size[1], i / (size[0] * size[1])};
    for (int axis = 0; axis < 3; ++axis) {
      const float step = path + float(spacing[axis]);
      if (step > reach) continue;
      for (const bool up : {false, true}) {
        if (up ? at[axis] + 1 == size[axis] : at[axis] == 0) continue;
        const std::size_t j = up ? i + strides[axis] : i - strides[axis];
        if (step >= pathMm[j] || step > reachAt(j)) continue;
        if (pathMm[j] == unreached) { // first reached: fluid the k-NN calls brain (not ventricles), tissue before surgery
          if (!isFluid[j] || !isBrainLabel(out[j]) || out[j] == Ventricles || !showedTissue(j)) continue;
          out[j] = Background;
          ++joined;
        }
        pathMm[j] = step;
        front.push({step, j});
      }
    }
  }
  return joined;
}

/// Thick fluid (or air) in the brain: ventricles where the aligned ventricles are (30 % of a body
/// within 2 mm of them), else a gap or cavity (background), which takes the fluid next to it that
/// was tissue before surgery (joinFluidToGaps; with P.preopLook). Thin fluid far from the
/// ventricles is a sulcus, part of the parenchyma.
void separateThickFluid(const ClassificationWork& w, TissueClassificationResult& result, LabelPixel* out)
{
  const MaskImage::Pointer fluid = fluidInBrain(w, result, out);
  auto labelled = components<unsigned>(thickPartOf(w, fluid), false);
  const unsigned* component = labelled->GetBufferPointer();
  std::map<unsigned, std::pair<std::size_t, std::size_t>> overlap; // component -> (in ventricles, all)
  const std::size_t ventricleSlot = w.slotOf(Ventricles);
  for (std::size_t i = 0; i < w.N; ++i) {
    if (!component[i]) continue;
    auto& o = overlap[component[i]];
    o.second += 1;
    o.first += w.distance(i, ventricleSlot) <= 2.0f;
  }
  std::vector<std::size_t> gaps;
  for (std::size_t i = 0; i < w.N; ++i) {
    if (component[i]) {
      const auto& o = overlap[component[i]];
      const bool ventricle = double(o.first) >= 0.3 * double(o.second);
      if (!ventricle) gaps.push_back(i);
      if (!isBrainLabel(out[i])) continue; // the head's or background's own voxels keep their label
      out[i] = ventricle ? Ventricles : Background;
    } else if (out[i] == Ventricles && w.distance(i, ventricleSlot) > 0.5f * float(w.P.saturationMm)) {
      out[i] = Parenchyma;
    }
  }
  // Not where the fluid is brighter than the parenchyma (T2): there the cortex with its CSF looks
  // like fluid, and grown through it the gaps took cortex (the small T2 case: 15.6 ml, brain Dice
  // 0.956 -> 0.950), as the aligned brain's thickness did (fluidInBrain).
  if (w.P.preopLook && !result.contrast.fluidBrighterThanParenchyma()) {
    const auto s = w.intraop.GetSpacing();
    result.fluidJoinedToGapsMl = double(joinFluidToGaps(w, *fluid, gaps, result.tumourResected, out)) * s[0] * s[1] * s[2] / 1000.0;
  }
}

/// The brain is one piece: brain voxels outside its largest component become head. Returns the brain.
MaskImage::Pointer keepLargestBrainComponent(const ClassificationWork& w, LabelPixel* out)
{
  MaskImage::Pointer brain = maskOnGrid(w.intraop);
  for (std::size_t i = 0; i < w.N; ++i) brain->GetBufferPointer()[i] = isBrainLabel(out[i]);
  auto largest = components<unsigned>(brain, true);
  for (std::size_t i = 0; i < w.N; ++i) {
    if (isBrainLabel(out[i]) && largest->GetBufferPointer()[i] != 1) {
      out[i] = Head;
      brain->GetBufferPointer()[i] = 0;
    }
  }
  return brain;
}

/// Holes in the brain smaller than P.smallHoleMl (not touching the grid's border) are filled with
/// parenchyma; the cavity and the gap are larger.
void fillSmallHoles(const ClassificationWork& w, const MaskImage::Pointer& brain, LabelPixel* out)
{
  auto outside = MaskImage::New();
  outside->CopyInformation(brain);
  outside->SetRegions(brain->GetLargestPossibleRegion());
  outside->Allocate();
  for (std::size_t i = 0; i < w.N; ++i) outside->GetBufferPointer()[i] = !brain->GetBufferPointer()[i];
  auto holes = components<unsigned>(outside, false);
  const unsigned* h = holes->GetBufferPointer();
  std::map<unsigned, std::size_t> volume;
  std::set<unsigned> touchesBorder;
  const auto size = w.size;
  for (std::size_t i = 0; i < w.N; ++i) {
    if (!h[i]) continue;
    volume[h[i]] += 1;
    const std::size_t x = i % size[0], y = (i / size[0]) % size[1], z = i / (size[0] * size[1]);
    if (x == 0 || y == 0 || z == 0 || x + 1 == size[0] || y + 1 == size[1] || z + 1 == size[2]) touchesBorder.insert(h[i]);
  }
  const double voxelMl = w.intraop.GetSpacing()[0] * w.intraop.GetSpacing()[1] * w.intraop.GetSpacing()[2] / 1000.0;
  for (std::size_t i = 0; i < w.N; ++i) {
    if (h[i] && !touchesBorder.count(h[i]) && double(volume[h[i]]) * voxelMl < w.P.smallHoleMl) out[i] = Parenchyma;
  }
}

/// Clean-up of the k-NN's brain: thick fluid separated, a resected tumour's voxels to the
/// background, one piece, small holes filled.
void cleanUpBrain(const ClassificationWork& w, TissueClassificationResult& result)
{
  throwIfCancelled(w.P.cancel, "tissue classification");
  LabelPixel* out = result.labels->GetBufferPointer();
  if (w.maps->present.count(Ventricles)) separateThickFluid(w, result, out);
  if (result.tumourResected) {
    for (std::size_t i = 0; i < w.N; ++i) {
      if (out[i] == Tumour) out[i] = Background;
    }
  }
  fillSmallHoles(w, keepLargestBrainComponent(w, out), out);
}

void warnOfResectionByImage(TissueClassificationResult& result)
{
  if (!result.tumourResected || result.tumourEvidence.decidedBy != "image") return;
  std::ostringstream w;
  w.precision(2);
  w << TumourLooksResectedWarning << " (" << std::lround(100 * result.tumourEvidence.fluidLikeShare)
    << " % of its prototypes look like fluid, " << std::lround(100 * result.tumourEvidence.tumourLikeShare)
    << " % like the tumour before surgery); --tumour-resected no if it is not";
  result.warnings.push_back(w.str());
}

/// Where the fluid is brighter than the parenchyma (T2), the fluid pooled under a craniotomy looks
/// like the cortex beneath it: CSF in the sulci makes the cortex's first millimetres as bright
/// (rf10-t2, under the craniotomy: the gap's fluid 654 median, the true brain's outer 3 mm 577,
/// its 90th percentile 874). Neither intensity nor the spatial prior (the fluid fills where the
/// brain was) tells them apart, and the brain is drawn up to the fluid's surface. Said, with what
/// it costs on the built-in T2 scenarios (in round figures, which a rerun of the scenarios does not
/// outdate: results/scenarios), since the confidence map does not see it.
void warnOfFluidLikeCortex(TissueClassificationResult& result)
{
  if (!result.contrast.fluidBrighterThanParenchyma()) return;
  result.warnings.push_back(
    "classify: this scan's fluid is brighter than its parenchyma (T2-like), and fluid pooled under the craniotomy looks like "
    "the cortex beneath it: the brain's boundary there may be drawn at the fluid's surface, above the sunken brain (on the "
    "built-in T2 scenarios more than 1 mm on average and 3-4 mm at the 95th percentile, where the other contrasts stay "
    "within 1 mm), and the confidence map does not show it; check the brain's boundary under the craniotomy on the scan");
}

} // namespace

TissueClassificationResult classifyTissues(const ScalarImage& intraop, const LabelImage& preopLabels,
                                           const SpatialTransform& rigid,
                                           const std::optional<std::vector<TissuePrototype>>& given,
                                           const TissueClassificationParameters& P)
{
  P.validate();
  TissueClassificationResult result;
  const auto start = Clock::now();
  ClassificationWork work(intraop, P, tissueMapsFor(preopLabels, P));
  result.voxels = work.N;
  sampleAlignedDistances(work, rigid);
  computeFeatures(work);
  result.intensityScale = work.intensityScale;
  if (given) {
    takeGivenPrototypes(work, *given, result);
  } else {
    choosePrototypes(work, result);
  }
  std::vector<LabelPixel> cloudLabels;
  PrototypeCloud cloud = learnFromPrototypes(work, result, cloudLabels);
  result.featureSeconds = secondsSince(start);

  const auto knnStart = Clock::now();
  labelByNearestPrototypes(work, cloud, cloudLabels, result);
  result.knnSeconds = secondsSince(knnStart);

  const auto cleanupStart = Clock::now();
  cleanUpBrain(work, result);
  result.cleanupSeconds = secondsSince(cleanupStart);
  warnOfResectionByImage(result);
  warnOfFluidLikeCortex(result);
  return result;
}

// ---- Prototype files --------------------------------------------------------------------------
namespace {
LabelPixel labelFromName(const std::string& name, const fs::path& path)
{
  const std::string head = name.substr(0, name.find('-'));
  for (LabelPixel l = 0; l <= 4; ++l) {
    if (head == tissueName(l) || (head == "tumor" && l == Tumour)) return l;
  }
  try {
    std::size_t used = 0;
    const int value = std::stoi(head, &used);
    if (used == head.size() && value >= 0 && value <= 65535) return LabelPixel(value);
  } catch (const std::exception&) {
  }
  throw InputError(path.string() + ": prototype '" + name +
                   "' names no tissue (start the name with a label number or background, head, parenchyma, ventricles, tumour)");
}
} // namespace

std::vector<TissuePrototype> readPrototypes(const fs::path& path)
{
  const std::string name = path.filename().string();
  if (name.size() > 9 && name.substr(name.size() - 9) == ".mrk.json") {
    std::vector<TissuePrototype> prototypes;
    for (const NamedPoint& point : readMarkupsJson(path)) {
      prototypes.push_back({point.name, labelFromName(point.name, path), point.position});
    }
    return prototypes;
  }
  nlohmann::json document;
  try {
    document = nlohmann::json::parse(readTextFile(path));
  } catch (const nlohmann::json::exception& e) {
    throw InputError(path.string() + ": not a prototype file: " + e.what());
  }
  if (!document.is_object() || document.value("frame", "") != "intraop" || !document.contains("prototypes")) {
    throw InputError(path.string() + ": not a prototype file (expected {\"frame\": \"intraop\", \"prototypes\": [...]})");
  }
  std::vector<TissuePrototype> prototypes;
  for (const auto& p : document["prototypes"]) {
    TissuePrototype prototype;
    prototype.name = p.value("name", "");
    if (!p.contains("label") || !p["label"].is_number_integer() || !p.contains("position") || p["position"].size() != 3) {
      throw InputError(path.string() + ": prototype '" + prototype.name + "' needs an integer label and a 3D position");
    }
    prototype.label = LabelPixel(p["label"].get<int>());
    for (int i = 0; i < 3; ++i) prototype.position[i] = p["position"][i].get<double>();
    prototypes.push_back(prototype);
  }
  return prototypes;
}

void writePrototypes(const std::vector<TissuePrototype>& prototypes, const fs::path& path)
{
  nlohmann::json list = nlohmann::json::array();
  for (const TissuePrototype& p : prototypes) {
    list.push_back({{"name", p.name}, {"label", p.label}, {"position", {p.position[0], p.position[1], p.position[2]}}});
  }
  const nlohmann::json document = {{"frame", "intraop"}, {"coordinate_system", "LPS"}, {"prototypes", list}};
  writeTextFileAtomically(path, document.dump(1) + "\n");
}

} // namespace brainshift
