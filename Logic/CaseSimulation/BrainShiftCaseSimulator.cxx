#include "BrainShiftCaseSimulator.h"

#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "DistanceMaps.h"
#include "FiniteElementTruth.h"
#include "IntensityStatistics.h"
#include "NumberText.h"
#include "VolumeIO.h"

#include <itkCompositeTransform.h>
#include <itkConnectedComponentImageFilter.h>
#include <itkDisplacementFieldTransform.h>
#include <itkEuler3DTransform.h>
#include <itkMultiThreaderBase.h>
#include <itkRelabelComponentImageFilter.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <map>
#include <cmath>
#include <numeric>
#include <limits>
#include <random>

namespace brainshift {
namespace fs = std::filesystem;

namespace {

using Vec3 = std::array<double, 3>;

enum Label : LabelPixel { Background = 0, Head = 1, Parenchyma = 2, Ventricles = 3, Tumour = 4 };

Vec3 operator+(const Vec3& a, const Vec3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
Vec3 operator-(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3 operator*(double s, const Vec3& a) { return {s * a[0], s * a[1], s * a[2]}; }
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double norm(const Vec3& a) { return std::sqrt(dot(a, a)); }
Vec3 normalized(const Vec3& a) { return (1.0 / norm(a)) * a; }
Vec3 toVec(const PhysicalPoint& p) { return {p[0], p[1], p[2]}; }
PhysicalPoint toPoint(const Vec3& v)
{
  PhysicalPoint p;
  for (int i = 0; i < 3; ++i) p[i] = v[i];
  return p;
}

/// The index <-> physical mapping of an image grid, for fast loops without virtual calls.
struct Grid {
  std::array<std::size_t, 3> size{};
  Vec3 spacing{}, origin{};
  double direction[3][3]{};

  template <class TImage>
  static Grid of(const TImage* image)
  {
    Grid g;
    for (int i = 0; i < 3; ++i) {
      g.size[i] = image->GetLargestPossibleRegion().GetSize()[i];
      g.spacing[i] = image->GetSpacing()[i];
      g.origin[i] = image->GetOrigin()[i];
      for (int j = 0; j < 3; ++j) g.direction[i][j] = image->GetDirection()(i, j);
    }
    return g;
  }
  std::size_t count() const { return size[0] * size[1] * size[2]; }
  std::size_t offset(std::size_t i, std::size_t j, std::size_t k) const { return i + size[0] * (j + size[1] * k); }
  std::array<std::size_t, 3> indexOf(std::size_t offset) const
  {
    return {offset % size[0], (offset / size[0]) % size[1], offset / (size[0] * size[1])};
  }
  Vec3 point(double i, double j, double k) const
  {
    const double idx[3] = {i * spacing[0], j * spacing[1], k * spacing[2]};
    Vec3 p = origin;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) p[r] += direction[r][c] * idx[c];
    }
    return p;
  }
  Vec3 pointOf(std::size_t offset) const
  {
    const auto idx = indexOf(offset);
    return point(double(idx[0]), double(idx[1]), double(idx[2]));
  }
  Vec3 continuousIndex(const Vec3& p) const
  {
    const Vec3 d = p - origin;
    Vec3 idx{};
    for (int c = 0; c < 3; ++c) {
      double s = 0;
      for (int r = 0; r < 3; ++r) s += direction[r][c] * d[r];
      idx[c] = s / spacing[c];
    }
    return idx;
  }
  template <class TImage>
  void applyTo(TImage* image) const
  {
    typename TImage::RegionType region;
    typename TImage::SizeType s;
    typename TImage::SpacingType sp;
    typename TImage::PointType o;
    typename TImage::DirectionType d;
    for (int i = 0; i < 3; ++i) {
      s[i] = size[i];
      sp[i] = spacing[i];
      o[i] = origin[i];
      for (int j = 0; j < 3; ++j) d(i, j) = direction[i][j];
    }
    region.SetSize(s);
    image->SetRegions(region);
    image->SetSpacing(sp);
    image->SetOrigin(o);
    image->SetDirection(d);
    image->Allocate();
  }
};

template <class TImage>
typename TImage::Pointer newImage(const Grid& grid, typename TImage::PixelType fill)
{
  auto image = TImage::New();
  grid.applyTo(image.GetPointer());
  image->FillBuffer(fill);
  return image;
}

/// Trilinear interpolation of a scalar buffer; `outside` beyond the grid.
template <class T>
double sampleLinear(const Grid& g, const T* data, const Vec3& p, double outside)
{
  const Vec3 c = g.continuousIndex(p);
  std::size_t base[3];
  double f[3];
  for (int i = 0; i < 3; ++i) {
    if (!(c[i] >= 0.0) || c[i] > double(g.size[i] - 1)) return outside;
    const double fl = std::min(std::floor(c[i]), double(g.size[i] >= 2 ? g.size[i] - 2 : 0));
    base[i] = std::size_t(fl);
    f[i] = c[i] - fl;
  }
  double value = 0;
  for (int corner = 0; corner < 8; ++corner) {
    const int dx = corner & 1, dy = (corner >> 1) & 1, dz = (corner >> 2) & 1;
    const double w = (dx ? f[0] : 1 - f[0]) * (dy ? f[1] : 1 - f[1]) * (dz ? f[2] : 1 - f[2]);
    if (w == 0) continue;
    value += w * double(data[g.offset(base[0] + dx, base[1] + dy, base[2] + dz)]);
  }
  return value;
}

template <class T>
T sampleNearest(const Grid& g, const T* data, const Vec3& p, T outside)
{
  const Vec3 c = g.continuousIndex(p);
  std::size_t idx[3];
  for (int i = 0; i < 3; ++i) {
    const double r = std::round(c[i]);
    if (r < 0 || r > double(g.size[i] - 1)) return outside;
    idx[i] = std::size_t(r);
  }
  return data[g.offset(idx[0], idx[1], idx[2])];
}

/// The displacement w on the field grid (double vectors), trilinear; zero outside.
Vec3 sampleField(const Grid& g, const itk::Vector<double, 3>* field, const Vec3& p)
{
  const Vec3 c = g.continuousIndex(p);
  std::size_t base[3];
  double f[3];
  for (int i = 0; i < 3; ++i) {
    if (!(c[i] >= 0.0) || c[i] > double(g.size[i] - 1)) return {0, 0, 0};
    const double fl = std::min(std::floor(c[i]), double(g.size[i] - 2));
    base[i] = std::size_t(fl);
    f[i] = c[i] - fl;
  }
  Vec3 value{0, 0, 0};
  for (int corner = 0; corner < 8; ++corner) {
    const int dx = corner & 1, dy = (corner >> 1) & 1, dz = (corner >> 2) & 1;
    const double w = (dx ? f[0] : 1 - f[0]) * (dy ? f[1] : 1 - f[1]) * (dz ? f[2] : 1 - f[2]);
    const auto& v = field[g.offset(base[0] + dx, base[1] + dy, base[2] + dz)];
    for (int k = 0; k < 3; ++k) value[k] += w * v[k];
  }
  return value;
}

void parallelFor(std::size_t count, const std::function<void(std::size_t)>& body)
{
  auto threader = itk::MultiThreaderBase::New();
  threader->ParallelizeArray(0, count, body, nullptr);
}

/// A counter-based hash in [0, 1): deterministic texture independent of thread order.
double hashUniform(std::uint64_t seed, std::uint64_t i)
{
  std::uint64_t z = seed * 0x9E3779B97F4A7C15ull + i + 0x632BE59BD9B4E019ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  return double(z >> 11) * (1.0 / 9007199254740992.0);
}

// ---- Masks --------------------------------------------------------------------------------
MaskImage::Pointer largestComponent(const MaskImage* mask)
{
  auto components = itk::ConnectedComponentImageFilter<MaskImage, itk::Image<unsigned, 3>>::New();
  components->SetInput(mask);
  auto relabel = itk::RelabelComponentImageFilter<itk::Image<unsigned, 3>, itk::Image<unsigned, 3>>::New();
  relabel->SetInput(components->GetOutput());
  relabel->Update();
  auto out = MaskImage::New();
  out->CopyInformation(mask);
  out->SetRegions(mask->GetLargestPossibleRegion());
  out->Allocate();
  const unsigned* in = relabel->GetOutput()->GetBufferPointer();
  const std::size_t n = mask->GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) out->GetBufferPointer()[i] = in[i] == 1 ? 1 : 0;
  return out;
}


/// Fills the holes of each axial slice (background not connected to the slice's border).
void fillHolesPerSlice(MaskImage* mask, const Grid& g)
{
  unsigned char* m = mask->GetBufferPointer();
  std::vector<unsigned char> outside(g.size[0] * g.size[1]);
  std::vector<std::size_t> stack;
  for (std::size_t k = 0; k < g.size[2]; ++k) {
    std::fill(outside.begin(), outside.end(), 0);
    auto at = [&](std::size_t i, std::size_t j) { return m[g.offset(i, j, k)]; };
    auto push = [&](std::size_t i, std::size_t j) {
      const std::size_t o = i + g.size[0] * j;
      if (!outside[o] && !at(i, j)) {
        outside[o] = 1;
        stack.push_back(o);
      }
    };
    for (std::size_t i = 0; i < g.size[0]; ++i) {
      push(i, 0);
      push(i, g.size[1] - 1);
    }
    for (std::size_t j = 0; j < g.size[1]; ++j) {
      push(0, j);
      push(g.size[0] - 1, j);
    }
    while (!stack.empty()) {
      const std::size_t o = stack.back();
      stack.pop_back();
      const std::size_t i = o % g.size[0], j = o / g.size[0];
      if (i > 0) push(i - 1, j);
      if (i + 1 < g.size[0]) push(i + 1, j);
      if (j > 0) push(i, j - 1);
      if (j + 1 < g.size[1]) push(i, j + 1);
    }
    for (std::size_t j = 0; j < g.size[1]; ++j) {
      for (std::size_t i = 0; i < g.size[0]; ++i) {
        if (!outside[i + g.size[0] * j]) m[g.offset(i, j, k)] = 1;
      }
    }
  }
}

/// Averages blocks of 2x2x2 voxels: the anti-aliased 2 mm version of a 1 mm image.
ScalarImage::Pointer downsampleByTwo(const ScalarImage* image)
{
  const Grid in = Grid::of(image);
  Grid out = in;
  for (int i = 0; i < 3; ++i) {
    out.size[i] = (in.size[i] + 1) / 2;
    out.spacing[i] = in.spacing[i] * 2;
  }
  out.origin = in.point(0.5, 0.5, 0.5);
  auto result = newImage<ScalarImage>(out, 0.0f);
  const float* src = image->GetBufferPointer();
  float* dst = result->GetBufferPointer();
  parallelFor(out.size[2], [&](std::size_t k) {
    for (std::size_t j = 0; j < out.size[1]; ++j) {
      for (std::size_t i = 0; i < out.size[0]; ++i) {
        double sum = 0;
        int count = 0;
        for (int c = 0; c < 8; ++c) {
          const std::size_t ii = 2 * i + (c & 1), jj = 2 * j + ((c >> 1) & 1), kk = 2 * k + ((c >> 2) & 1);
          if (ii < in.size[0] && jj < in.size[1] && kk < in.size[2]) {
            sum += src[in.offset(ii, jj, kk)];
            ++count;
          }
        }
        dst[out.offset(i, j, k)] = float(sum / count);
      }
    }
  });
  return result;
}

Vec3 craniotomyDirection(CraniotomySite site)
{
  // Outward directions in LPS (x: left, y: posterior, z: superior).
  switch (site) {
  case CraniotomySite::RightFrontal: return normalized({-0.55, -0.55, 0.63});
  case CraniotomySite::LeftFrontal: return normalized({0.55, -0.55, 0.63});
  case CraniotomySite::RightParietal: return normalized({-0.6, 0.35, 0.72});
  case CraniotomySite::LeftParietal: return normalized({0.6, 0.35, 0.72});
  case CraniotomySite::Vertex: return normalized({0.0, 0.05, 1.0});
  }
  return {0, 0, 1};
}

/// Picks up to `count` candidates in random (seeded) order, each at least `separation` mm from
/// every point already chosen (including `taken`).
std::vector<Vec3> pickSeparated(std::vector<Vec3> candidates, std::size_t count, double separation,
                                std::vector<Vec3>& taken, std::mt19937_64& rng)
{
  std::shuffle(candidates.begin(), candidates.end(), rng);
  std::vector<Vec3> chosen;
  for (const Vec3& c : candidates) {
    if (chosen.size() == count) break;
    bool farEnough = true;
    for (const Vec3& t : taken) {
      if (norm(c - t) < separation) {
        farEnough = false;
        break;
      }
    }
    if (!farEnough) continue;
    chosen.push_back(c);
    taken.push_back(c);
  }
  return chosen;
}

/// The intraoperative scanner's contrast: a map of the white-matter-normalised preoperative T1
/// intensity v. T1 is a gamma of 0.85 (the built-in case as it always was); the others are
/// piecewise linear through the tissue means (air 0, CSF c, grey g, white 1, fat and scalp 2), with
/// values after published relative signal intensities at those field strengths and weightings.
class IntensityMap {
public:
  IntensityMap() = default;
  IntensityMap(std::vector<double> from, std::vector<double> to) : from_(std::move(from)), to_(std::move(to)) {}
  double operator()(double v) const
  {
    if (from_.empty()) return std::pow(v, 0.85);
    if (v <= from_.front()) return to_.front();
    for (std::size_t k = 1; k < from_.size(); ++k) {
      if (v <= from_[k] || k + 1 == from_.size()) {
        const double t = (v - from_[k - 1]) / (from_[k] - from_[k - 1]);
        return std::max(0.0, to_[k - 1] + t * (to_[k] - to_[k - 1]));
      }
    }
    return to_.back();
  }

private:
  std::vector<double> from_, to_;
};

IntensityMap intraopContrastMap(IntraopContrast contrast, double csf, double grey)
{
  const std::vector<double> anchors{0.0, csf, grey, 1.0, 2.0};
  switch (contrast) {
  case IntraopContrast::T1: return {};
  case IntraopContrast::LowFieldT1: return {anchors, {0.0, 0.55, 0.80, 0.92, 1.30}};
  case IntraopContrast::T2: return {anchors, {0.0, 1.00, 0.55, 0.42, 0.70}};
  case IntraopContrast::Flair: return {anchors, {0.0, 0.12, 0.80, 0.62, 0.70}};
  case IntraopContrast::T1PostContrast: return {}; // the T1 map; the enhancement is added where it is (enhanceAfterContrastAgent)
  }
  return {};
}

/// What a voxel of the preoperative brain holds in the deformed configuration.
enum Matter : unsigned char { Outside = 0, Tissue, Gap, Cavity };

/// The "up" of the patient on the table: the craniotomy axis tilted towards the posterior.
Vec3 upwardDirection(const Vec3& axis, double tiltDegrees)
{
  Vec3 towards{0, 1, 0};
  if (std::abs(dot(towards, axis)) > 0.9) towards = {0, 0, 1};
  const Vec3 perpendicular = normalized(towards - dot(towards, axis) * axis);
  const double t = tiltDegrees * M_PI / 180.0;
  return normalized(std::cos(t) * axis + std::sin(t) * perpendicular);
}

/// A slab field of view: the axial slices of the grid around `centreZ` (scanner z, mm), 75 mm in
/// all (30 slices of 2.5 mm; 15 of 5 mm for the small case), the in-plane field unchanged.
void cutToSlab(Grid& I, double centreZ, bool small)
{
  I.size[2] = small ? 15 : 30;
  I.origin[2] = centreZ - 0.5 * I.spacing[2] * double(I.size[2] - 1);
}

/// The height (along `up`) below which `fraction` of the voxels of one matter lie.
double fluidLevel(const Grid& g, const std::vector<unsigned char>& matter, Matter which, const Vec3& up, double fraction)
{
  std::vector<double> heights;
  for (std::size_t i = 0; i < matter.size(); ++i) {
    if (matter[i] == which) heights.push_back(dot(g.pointOf(i), up));
  }
  if (heights.empty()) return 0;
  const std::size_t at = std::min(heights.size() - 1, std::size_t(fraction * double(heights.size())));
  std::nth_element(heights.begin(), heights.begin() + std::ptrdiff_t(at), heights.end());
  return fraction >= 1.0 ? std::numeric_limits<double>::infinity() : heights[at];
}

/// The intensities of the intraoperative-only matter in the deformed image: the gap (one dark
/// value, or CSF-like fluid under air with a level set by gravity) and the resection cavity (fluid,
/// air above its own level, and a bright rim of blood products on its wall when asked).
void fillIntraoperativeMatter(const CaseParameters& P, const Grid& G, const Vec3& axis, double fluidValue, double whiteMean,
                              const std::vector<unsigned char>& matter, float* image, CaseFigures& figures)
{
  const bool fluidAndAir = P.gap == GapContent::FluidAndAir;
  const Vec3 up = upwardDirection(axis, P.gravityTiltDegrees);
  const double gapLevel = fluidAndAir ? fluidLevel(G, matter, Gap, up, P.gapFluidFraction) : 0.0;
  const double cavityLevel = fluidAndAir ? fluidLevel(G, matter, Cavity, up, P.cavityFluidFraction) : 0.0;
  const double voxelMl = G.spacing[0] * G.spacing[1] * G.spacing[2] / 1000.0;
  ScalarImage::Pointer toCavityWall;
  if (P.cavityRim) {
    auto cavity = newImage<MaskImage>(G, 0);
    for (std::size_t i = 0; i < matter.size(); ++i) cavity->GetBufferPointer()[i] = matter[i] == Cavity;
    toCavityWall = signedDistanceMm(cavity);
  }
  for (std::size_t i = 0; i < matter.size(); ++i) {
    if (matter[i] == Gap) {
      const bool air = fluidAndAir && dot(G.pointOf(i), up) > gapLevel;
      image[i] = fluidAndAir ? (air ? 0.0f : float(fluidValue)) : float(0.6 * fluidValue);
      if (air) figures.gapAirMl += voxelMl;
    } else if (matter[i] == Cavity) {
      const bool air = fluidAndAir && dot(G.pointOf(i), up) > cavityLevel;
      image[i] = air ? 0.0f : float(fluidValue);
      if (air) figures.cavityAirMl += voxelMl;
      if (!air && toCavityWall && toCavityWall->GetBufferPointer()[i] >= -1.5f) image[i] = float(1.25 * whiteMean);
    }
  }
}

/// T1 after gadolinium: what takes up the agent enhances strongly (1.6 of the white matter before
/// the T1 map): the rim of a tumour left in place (its outer 2.5 mm), the brain tissue lining a
/// resection cavity (3 mm) and the dura around the craniotomy's edge (3 mm outside the
/// preoperative brain, within 20 mm beyond the opening; under the opening it has been opened).
void enhanceAfterContrastAgent(const Grid& G, const std::vector<unsigned char>& matter, const LabelPixel* deformedLabels,
                               const float* brainDepth, const Vec3& craniotomyCentre, const Vec3& axis, double openingRadius,
                               double whiteMean, float* image)
{
  const float enhanced = float(1.6 * whiteMean);
  auto tumour = newImage<MaskImage>(G, 0);
  auto cavity = newImage<MaskImage>(G, 0);
  bool anyTumour = false, anyCavity = false;
  for (std::size_t i = 0; i < matter.size(); ++i) {
    tumour->GetBufferPointer()[i] = deformedLabels[i] == Tumour;
    cavity->GetBufferPointer()[i] = matter[i] == Cavity;
    anyTumour = anyTumour || deformedLabels[i] == Tumour;
    anyCavity = anyCavity || matter[i] == Cavity;
  }
  const ScalarImage::Pointer toTumour = anyTumour ? signedDistanceMm(tumour) : nullptr;
  const ScalarImage::Pointer toCavity = anyCavity ? signedDistanceMm(cavity) : nullptr;
  const double ringRadius = openingRadius + 20.0;
  for (std::size_t i = 0; i < matter.size(); ++i) {
    if (toTumour && deformedLabels[i] == Tumour && toTumour->GetBufferPointer()[i] >= -2.5f) image[i] = enhanced;
    if (toCavity && matter[i] == Tissue && toCavity->GetBufferPointer()[i] <= 3.0f) image[i] = enhanced;
    if (deformedLabels[i] == Head && brainDepth[i] > 0.0f && brainDepth[i] <= 3.0f) {
      const Vec3 d = G.pointOf(i) - craniotomyCentre;
      const double along = dot(d, axis);
      if (dot(d, d) - along * along < ringRadius * ringRadius && along > -openingRadius) image[i] = enhanced;
    }
  }
}

} // namespace

// ---- Parameters ---------------------------------------------------------------------------
std::string toString(CraniotomySite site)
{
  switch (site) {
  case CraniotomySite::RightFrontal: return "right-frontal";
  case CraniotomySite::LeftFrontal: return "left-frontal";
  case CraniotomySite::RightParietal: return "right-parietal";
  case CraniotomySite::LeftParietal: return "left-parietal";
  case CraniotomySite::Vertex: return "vertex";
  }
  return "";
}

CraniotomySite craniotomySiteFromString(const std::string& text)
{
  for (auto site : {CraniotomySite::RightFrontal, CraniotomySite::LeftFrontal, CraniotomySite::RightParietal,
                    CraniotomySite::LeftParietal, CraniotomySite::Vertex}) {
    if (toString(site) == text) return site;
  }
  throw InputError("--craniotomy: '" + text +
                   "' is not a site (right-frontal, left-frontal, right-parietal, left-parietal, vertex)");
}

namespace {
template <class TEnum>
TEnum enumFromString(const std::string& text, std::initializer_list<TEnum> values, const std::string& option)
{
  std::string choices;
  for (TEnum value : values) {
    if (toString(value) == text) return value;
    choices += (choices.empty() ? "" : ", ") + toString(value);
  }
  throw InputError(option + ": '" + text + "' is not one of " + choices);
}
} // namespace

std::string toString(IntraopContrast contrast)
{
  switch (contrast) {
  case IntraopContrast::T1: return "t1";
  case IntraopContrast::LowFieldT1: return "low-field-t1";
  case IntraopContrast::T2: return "t2";
  case IntraopContrast::Flair: return "flair";
  case IntraopContrast::T1PostContrast: return "t1-post-contrast";
  }
  return "";
}

IntraopContrast intraopContrastFromString(const std::string& text)
{
  return enumFromString(text, {IntraopContrast::T1, IntraopContrast::LowFieldT1, IntraopContrast::T2, IntraopContrast::Flair,
                                IntraopContrast::T1PostContrast},
                        "--contrast");
}

std::string toString(TumourAppearance appearance)
{
  switch (appearance) {
  case TumourAppearance::RimEnhancing: return "rim-enhancing";
  case TumourAppearance::Hypointense: return "hypointense";
  case TumourAppearance::NearlyIsointense: return "nearly-isointense";
  }
  return "";
}

TumourAppearance tumourAppearanceFromString(const std::string& text)
{
  return enumFromString(text, {TumourAppearance::RimEnhancing, TumourAppearance::Hypointense, TumourAppearance::NearlyIsointense},
                        "--tumour");
}

std::string toString(TruthModel truth)
{
  return truth == TruthModel::Kinematic ? "kinematic" : "finite-element-sliding";
}

TruthModel truthModelFromString(const std::string& text)
{
  return enumFromString(text, {TruthModel::Kinematic, TruthModel::FiniteElementSliding}, "--truth");
}

std::string toString(GapContent gap)
{
  return gap == GapContent::Dark ? "dark" : "fluid-and-air";
}

GapContent gapContentFromString(const std::string& text)
{
  return enumFromString(text, {GapContent::Dark, GapContent::FluidAndAir}, "--gap");
}

std::string toString(FieldOfView fieldOfView)
{
  return fieldOfView == FieldOfView::WholeHead ? "whole-head" : "slab";
}

FieldOfView fieldOfViewFromString(const std::string& text)
{
  return enumFromString(text, {FieldOfView::WholeHead, FieldOfView::Slab}, "--field-of-view");
}

void CaseParameters::validate() const
{
  auto require = [](bool ok, const std::string& message) {
    if (!ok) throw InputError(message);
  };
  require(std::isfinite(shiftMillimetres) && shiftMillimetres >= 0 && shiftMillimetres <= 25,
          "--shift: " + numberText(shiftMillimetres) + " mm is outside 0 to 25 mm");
  for (double r : rotationDegrees) {
    require(std::isfinite(r) && std::abs(r) <= 180, "--rotation: each angle must be within +-180 degrees");
  }
  for (double t : translationMillimetres) {
    require(std::isfinite(t) && std::abs(t) <= 50, "--translation: each component must be within +-50 mm");
  }
  require(std::isfinite(noiseFraction) && noiseFraction >= 0 && noiseFraction <= 0.5,
          "--noise: the noise fraction must be within 0 to 0.5");
  require(std::isfinite(biasStrength) && biasStrength >= 0 && biasStrength <= 1,
          "--bias: the bias strength must be within 0 to 1");
  require(std::isfinite(gapFluidFraction) && gapFluidFraction >= 0 && gapFluidFraction <= 1 &&
            std::isfinite(cavityFluidFraction) && cavityFluidFraction >= 0 && cavityFluidFraction <= 1,
          "the fluid fractions of the gap and the cavity must be within 0 to 1");
  require(std::isfinite(gravityTiltDegrees) && std::abs(gravityTiltDegrees) <= 60,
          "the gravity tilt must be within +-60 degrees");
  require(std::isfinite(tumourDepthMm) && tumourDepthMm >= 13 && tumourDepthMm <= 40,
          "--tumour-depth: " + numberText(tumourDepthMm) + " mm is outside 13 to 40 mm (the tumour's centre below the cortex)");
}

namespace {
/// Partial fields of view: the head scanned as a slab of axial slices around the craniotomy (new
/// names and seeds; fluid and air under the craniotomy as in every hard scenario).
void addSlabScenarios(std::vector<CaseScenario>& list)
{
  auto slab = [](std::uint64_t seed, CraniotomySite site, double shift, bool resection, TumourAppearance tumour,
                 IntraopContrast contrast, double noise, double bias) {
    CaseParameters p;
    p.seed = seed;
    p.craniotomy = site;
    p.shiftMillimetres = shift;
    p.resection = resection;
    p.tumourAppearance = tumour;
    p.contrast = contrast;
    p.noiseFraction = noise;
    p.biasStrength = bias;
    p.gap = GapContent::FluidAndAir;
    p.fieldOfView = FieldOfView::Slab;
    return p;
  };
  const std::string slabText = "; fluid and air under the craniotomy; scanned as a slab of 30 axial slices of 2.5 mm around the craniotomy";
  list.push_back({"rf10-slab", "right frontal, 10 mm, resection" + slabText,
                  slab(2151, CraniotomySite::RightFrontal, 10, true, TumourAppearance::RimEnhancing, IntraopContrast::T1, 0.04, 0.2)});
  list.push_back({"lp15-slab-intact", "left parietal, 15 mm, hypointense tumour in place" + slabText,
                  slab(2152, CraniotomySite::LeftParietal, 15, false, TumourAppearance::Hypointense, IntraopContrast::T1, 0.05, 0.25)});
  CaseParameters misaligned =
    slab(2153, CraniotomySite::RightParietal, 10, true, TumourAppearance::RimEnhancing, IntraopContrast::LowFieldT1, 0.04, 0.2);
  misaligned.rotationDegrees = {15.0, -12.0, 16.0};
  misaligned.translationMillimetres = {20.0, -15.0, 15.0};
  list.push_back({"rp10-slab-misaligned",
                  "right parietal, 10 mm, resection, low-field, head 25 degrees and 29 mm from the preoperative pose" + slabText, misaligned});
}
} // namespace

const std::vector<CaseScenario>& caseScenarios()
{
  static const std::vector<CaseScenario> scenarios = [] {
    struct Variant {
      const char* name;
      const char* description;
      CraniotomySite site;
      double shift;
      bool resection;
      TumourAppearance tumour;
      IntraopContrast contrast;
      bool cavityRim;
      double noise, bias;
      std::uint64_t seed;
      double tumourDepth = CaseParameters{}.tumourDepthMm;
    };
    using S = CraniotomySite;
    using T = TumourAppearance;
    using C = IntraopContrast;
    const Variant variants[] = {
      {"rf05-lowfield", "right frontal, 5 mm, resection, hypointense tumour, low-field", S::RightFrontal, 5, true, T::Hypointense, C::LowFieldT1, false, 0.04, 0.25, 2101},
      {"rf10-intact-lowfield", "right frontal, 10 mm, tumour in place (rim-enhancing), low-field", S::RightFrontal, 10, false, T::RimEnhancing, C::LowFieldT1, false, 0.05, 0.2, 2102},
      {"rf15-cavityrim", "right frontal, 15 mm, resection with a bright cavity rim, 5 % noise, 30 % bias", S::RightFrontal, 15, true, T::RimEnhancing, C::T1, true, 0.05, 0.3, 2103},
      {"rf20-lowfield", "right frontal, 20 mm, resection, low-field, 5 % noise", S::RightFrontal, 20, true, T::RimEnhancing, C::LowFieldT1, false, 0.05, 0.2, 2104},
      {"lf10-intact-isointense", "left frontal, 10 mm, nearly isointense tumour in place, low-field", S::LeftFrontal, 10, false, T::NearlyIsointense, C::LowFieldT1, false, 0.04, 0.2, 2105},
      {"lf15-noise8", "left frontal, 15 mm, resection with a bright rim, 8 % noise, 30 % bias", S::LeftFrontal, 15, true, T::RimEnhancing, C::T1, true, 0.08, 0.3, 2106},
      {"lf20-intact-hypointense", "left frontal, 20 mm, hypointense tumour in place, low-field", S::LeftFrontal, 20, false, T::Hypointense, C::LowFieldT1, false, 0.04, 0.2, 2107},
      {"rp05-intact-isointense-noise8", "right parietal, 5 mm, nearly isointense tumour in place, 8 % noise, 30 % bias", S::RightParietal, 5, false, T::NearlyIsointense, C::T1, false, 0.08, 0.3, 2108},
      {"rp10-misaligned", "right parietal, 10 mm, resection, low-field, head 25 degrees and 29 mm from the preoperative pose", S::RightParietal, 10, true, T::RimEnhancing, C::LowFieldT1, false, 0.04, 0.2, 2109},
      {"rp15-cavityrim-lowfield", "right parietal, 15 mm, resection with a bright rim, low-field", S::RightParietal, 15, true, T::Hypointense, C::LowFieldT1, true, 0.04, 0.25, 2110},
      {"lp10-intact-lowfield", "left parietal, 10 mm, rim-enhancing tumour in place, low-field, 5 % noise", S::LeftParietal, 10, false, T::RimEnhancing, C::LowFieldT1, false, 0.05, 0.2, 2111},
      {"lp15-noise8-lowfield", "left parietal, 15 mm, resection, low-field, 8 % noise, 30 % bias", S::LeftParietal, 15, true, T::RimEnhancing, C::LowFieldT1, false, 0.08, 0.3, 2112},
      {"lp20-cavityrim", "left parietal, 20 mm, resection with a bright rim", S::LeftParietal, 20, true, T::RimEnhancing, C::T1, true, 0.04, 0.2, 2113},
      {"rf10-t2", "right frontal, 10 mm, resection, a T2-weighted intraoperative scan", S::RightFrontal, 10, true, T::RimEnhancing, C::T2, false, 0.04, 0.2, 2114},
      {"rf10-flair", "right frontal, 10 mm, tumour in place, a FLAIR intraoperative scan", S::RightFrontal, 10, false, T::RimEnhancing, C::Flair, false, 0.04, 0.2, 2115},
      {"rf10-fe-sliding", "right frontal, 10 mm, resection, low-field; finite element truth (CalculiX, sliding brain surface)", S::RightFrontal, 10, true, T::RimEnhancing, C::LowFieldT1, false, 0.04, 0.2, 2116},
      {"lp15-fe-sliding-intact", "left parietal, 15 mm, tumour in place; finite element truth (CalculiX, sliding brain surface)", S::LeftParietal, 15, false, T::Hypointense, C::T1, false, 0.05, 0.25, 2117},
      {"rf10-t1post-intact", "right frontal, 10 mm, tumour in place, a T1 post-contrast intraoperative scan (enhancing tumour rim and dura)", S::RightFrontal, 10, false, T::RimEnhancing, C::T1PostContrast, false, 0.04, 0.2, 2118},
      {"rf10-t1post", "right frontal, 10 mm, resection, a T1 post-contrast intraoperative scan (enhancing cavity wall and dura)", S::RightFrontal, 10, true, T::RimEnhancing, C::T1PostContrast, false, 0.04, 0.2, 2119},
      {"rf10-t2-intact", "right frontal, 10 mm, tumour in place, a T2-weighted intraoperative scan", S::RightFrontal, 10, false, T::RimEnhancing, C::T2, false, 0.04, 0.2, 2120},
      // A tumour reaching the cortex sinks with the brain: its place through the rigid prior holds
      // the gap's fluid, and it looks resected there.
      {"rf20-superficial-intact", "right frontal, 20 mm, nearly isointense tumour in place reaching the cortex, low-field", S::RightFrontal, 20, false, T::NearlyIsointense, C::LowFieldT1, false, 0.04, 0.2, 2121, 13.0},
      {"lp15-fe-superficial-intact", "left parietal, 15 mm, nearly isointense tumour in place reaching the cortex; finite element truth (CalculiX, sliding brain surface)", S::LeftParietal, 15, false, T::NearlyIsointense, C::T1, false, 0.04, 0.2, 2122, 13.0},
    };
    std::vector<CaseScenario> list{{"default", "the built-in case: right frontal, 10 mm, resection, T1, a dark gap", CaseParameters{}}};
    for (const Variant& v : variants) {
      CaseParameters p;
      p.seed = v.seed;
      p.craniotomy = v.site;
      p.shiftMillimetres = v.shift;
      p.resection = v.resection;
      p.tumourAppearance = v.tumour;
      p.contrast = v.contrast;
      p.cavityRim = v.cavityRim;
      p.noiseFraction = v.noise;
      p.biasStrength = v.bias;
      p.tumourDepthMm = v.tumourDepth;
      p.gap = GapContent::FluidAndAir; // every hard scenario: fluid under air in the gap and the cavity
      if (std::string(v.name).find("-fe-") != std::string::npos) p.truth = TruthModel::FiniteElementSliding;
      if (std::string(v.name) == "rp10-misaligned") {
        p.rotationDegrees = {15.0, -12.0, 16.0};
        p.translationMillimetres = {20.0, -15.0, 15.0};
      }
      list.push_back({v.name, std::string(v.description) + "; fluid and air under the craniotomy", p});
    }
    addSlabScenarios(list);
    return list;
  }();
  return scenarios;
}

const CaseScenario& caseScenario(const std::string& name)
{
  std::string names;
  for (const CaseScenario& scenario : caseScenarios()) {
    if (scenario.name == name) return scenario;
    names += (names.empty() ? "" : ", ") + scenario.name;
  }
  throw InputError("--scenario: '" + name + "' is not a scenario (" + names + ")");
}

CaseFiles::CaseFiles(const fs::path& caseFolder)
  : folder(caseFolder)
  , preopImage(caseFolder / "preop_image.nii.gz")
  , preopLabels(caseFolder / "preop_labels.nii.gz")
  , preopFmri(caseFolder / "preop_fmri.nii.gz")
  , intraopImage(caseFolder / "intraop_image.nii.gz")
  , landmarks(caseFolder / "landmarks.csv")
  , truthIntraopLabels(caseFolder / "truth" / "intraop_labels.nii.gz")
  , truthTransform(caseFolder / "truth" / "intraop_to_preop.h5")
  , truthRigidTransform(caseFolder / "truth" / "rigid_intraop_to_preop.tfm")
  , description(caseFolder / "case.json")
{
}

// ---- The simulation -----------------------------------------------------------------------
namespace {

using Euler = itk::Euler3DTransform<double>;
using DoubleField = itk::Image<itk::Vector<double, 3>, 3>;

/// The Colin27 T1 and its brain-extracted image as a 0/1 mask, both at 2 mm for the small case.
struct Colin27 {
  ScalarImage::Pointer t1, brain;
};

Colin27 readColin27(const CaseParameters& P, bool small)
{
  const fs::path t1Path = P.templateFolder / "ch2.nii.gz";
  const fs::path betPath = P.templateFolder / "ch2bet.nii.gz";
  for (const fs::path& path : {t1Path, betPath}) {
    std::error_code ec;
    if (!fs::exists(path, ec)) {
      throw InputError(path.string() + ": the Colin27 template is missing (install the Debian package mricron-data)");
    }
  }
  ScalarImage::Pointer t1 = readScalarVolume(t1Path);
  ScalarImage::Pointer bet = readScalarVolume(betPath);
  if (!ImageGeometry::of(t1.GetPointer()).sameGridAs(ImageGeometry::of(bet.GetPointer()))) {
    throw InputError(betPath.string() + ": not on the grid of " + t1Path.string());
  }
  {
    // The brain-extracted image as a 0/1 mask before any downsampling.
    float* b = bet->GetBufferPointer();
    for (std::size_t i = 0, n = bet->GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) b[i] = b[i] > 0 ? 1.f : 0.f;
  }
  if (small) {
    t1 = downsampleByTwo(t1);
    bet = downsampleByTwo(bet);
  }
  return {t1, bet};
}

/// The means of the template's CSF, grey and white matter inside the brain.
struct TissueMeans {
  double csf = 0, grey = 0, white = 0;
};

/// The preoperative anatomy on the template's grid, as every later phase reads it.
struct Anatomy {
  Grid G;
  std::size_t N = 0;
  double voxelMl = 0;
  ScalarImage::Pointer t1;
  MaskImage::Pointer brainMask, headMask, ventricleMask;
  ScalarImage::Pointer brainDistance; ///< signed distance to the brain's surface, mm (negative inside)
  TissueMeans tissue;
  Vec3 brainCentroid{0, 0, 0};

  const float* intensity() const { return t1->GetBufferPointer(); }
  const unsigned char* brain() const { return brainMask->GetBufferPointer(); }
  const unsigned char* head() const { return headMask->GetBufferPointer(); }
  const unsigned char* ventricles() const { return ventricleMask->GetBufferPointer(); }
  const float* brainDepth() const { return brainDistance->GetBufferPointer(); }
};

MaskImage::Pointer brainMaskOf(const ScalarImage* brainExtracted, const Grid& G)
{
  auto brainMask = newImage<MaskImage>(G, 0);
  for (std::size_t i = 0; i < G.count(); ++i) brainMask->GetBufferPointer()[i] = brainExtracted->GetBufferPointer()[i] >= 0.5f;
  brainMask = largestComponent(brainMask);
  fillHolesPerSlice(brainMask, G);
  return brainMask;
}

/// The head: brighter than half the template's two-class Otsu threshold, or brain, in one piece.
MaskImage::Pointer headMaskOf(const float* intensity, float maxIntensity, const unsigned char* brain, const Grid& G)
{
  const std::size_t N = G.count();
  const double headThreshold = 0.5 * otsuThresholds(intensity, N, 2, 0, maxIntensity)[0];
  auto headMask = newImage<MaskImage>(G, 0);
  for (std::size_t i = 0; i < N; ++i) headMask->GetBufferPointer()[i] = intensity[i] > headThreshold || brain[i];
  headMask = largestComponent(headMask);
  {
    // Close small gaps (2 mm) so that the skull, dark in T1, is enclosed by the scalp.
    ScalarImage::Pointer outside = signedDistanceMm(headMask);
    auto dilated = newImage<MaskImage>(G, 0);
    for (std::size_t i = 0; i < N; ++i) dilated->GetBufferPointer()[i] = outside->GetBufferPointer()[i] <= 2.0f;
    ScalarImage::Pointer inside = signedDistanceMm(dilated);
    for (std::size_t i = 0; i < N; ++i) headMask->GetBufferPointer()[i] = inside->GetBufferPointer()[i] <= -2.0f || brain[i];
  }
  fillHolesPerSlice(headMask, G);
  return headMask;
}

/// CSF, grey and white matter by three-class Otsu inside the brain.
TissueMeans tissueMeansOf(const float* intensity, float maxIntensity, const unsigned char* brain, std::size_t N)
{
  const std::vector<double> brainThresholds = otsuThresholds(intensity, N, 3, 0, maxIntensity, brain);
  double classSum[3] = {0, 0, 0}, classCount[3] = {0, 0, 0};
  for (std::size_t i = 0; i < N; ++i) {
    if (!brain[i]) continue;
    const int c = intensity[i] < brainThresholds[0] ? 0 : intensity[i] < brainThresholds[1] ? 1 : 2;
    classSum[c] += intensity[i];
    classCount[c] += 1;
  }
  TissueMeans means;
  means.csf = classSum[0] / classCount[0];
  means.grey = classSum[1] / classCount[1];
  means.white = classSum[2] / classCount[2];
  return means;
}

Vec3 centroidOf(const Grid& G, const unsigned char* mask)
{
  Vec3 centroid{0, 0, 0};
  double count = 0;
  for (std::size_t i = 0; i < G.count(); ++i) {
    if (mask[i]) {
      centroid = centroid + G.pointOf(i);
      count += 1;
    }
  }
  return (1.0 / count) * centroid;
}

/// A morphological opening of `mask` by `radiusMm`, through distance maps.
void openMask(MaskImage* mask, const Grid& G, double radiusMm)
{
  unsigned char* m = mask->GetBufferPointer();
  ScalarImage::Pointer toMask = signedDistanceMm(mask);
  auto eroded = newImage<MaskImage>(G, 0);
  for (std::size_t i = 0; i < G.count(); ++i) eroded->GetBufferPointer()[i] = toMask->GetBufferPointer()[i] <= -radiusMm + 1e-3;
  ScalarImage::Pointer toEroded = signedDistanceMm(eroded);
  for (std::size_t i = 0; i < G.count(); ++i) m[i] = m[i] && toEroded->GetBufferPointer()[i] <= radiusMm + 1e-3;
}

/// Keeps the connected pieces of `mask` of 1 ml or more that hold at least 0.2 ml of seed: voxels at
/// least 12 mm deep within 40 mm of the brain's centre.
void keepSeededPieces(MaskImage* mask, const Anatomy& a)
{
  auto components = itk::ConnectedComponentImageFilter<MaskImage, itk::Image<unsigned, 3>>::New();
  components->SetInput(mask);
  components->Update();
  const unsigned* component = components->GetOutput()->GetBufferPointer();
  const float* brainDepth = a.brainDepth();
  std::map<unsigned, std::size_t> seedVoxels, size;
  for (std::size_t i = 0; i < a.N; ++i) {
    if (!component[i]) continue;
    size[component[i]] += 1;
    if (brainDepth[i] <= -12.0f && norm(a.G.pointOf(i) - a.brainCentroid) < 40.0) seedVoxels[component[i]] += 1;
  }
  const double minimumVoxels = 1.0 / a.voxelMl;
  for (std::size_t i = 0; i < a.N; ++i) {
    const unsigned c = component[i];
    mask->GetBufferPointer()[i] = c && double(seedVoxels[c]) * a.voxelMl >= 0.2 && double(size[c]) >= minimumVoxels;
  }
}

/// The ventricular system is the thick dark CSF (opened by 1.5 mm, so that thin sulcal CSF drops
/// out) at least 4 mm inside the brain that connects to a seed: dark CSF at least 12 mm deep within
/// 40 mm of the brain's centre, in pieces of 1 ml or more.
MaskImage::Pointer ventricleMaskOf(const Anatomy& a)
{
  const unsigned char* brain = a.brain();
  const float* brainDepth = a.brainDepth();
  const float* intensity = a.intensity();
  auto ventricleMask = newImage<MaskImage>(a.G, 0);
  const double csfThreshold = 0.5 * (a.tissue.csf + a.tissue.grey);
  std::vector<unsigned char> darkDeep(a.N);
  for (std::size_t i = 0; i < a.N; ++i) {
    darkDeep[i] = brain[i] && brainDepth[i] <= -4.0f && intensity[i] < csfThreshold;
    ventricleMask->GetBufferPointer()[i] = darkDeep[i];
  }
  openMask(ventricleMask, a.G, 1.5);
  keepSeededPieces(ventricleMask, a);
  // Give back what the opening trimmed: the dark CSF within 2 mm of the ventricles kept.
  ScalarImage::Pointer toVentricles = signedDistanceMm(ventricleMask);
  for (std::size_t i = 0; i < a.N; ++i) {
    ventricleMask->GetBufferPointer()[i] = darkDeep[i] && toVentricles->GetBufferPointer()[i] <= 2.0f;
  }
  return ventricleMask;
}

Anatomy preoperativeAnatomy(const CaseParameters& P, bool small)
{
  const Colin27 colin = readColin27(P, small);
  Anatomy a;
  a.t1 = colin.t1;
  a.G = Grid::of(a.t1.GetPointer());
  a.N = a.G.count();
  a.voxelMl = a.G.spacing[0] * a.G.spacing[1] * a.G.spacing[2] / 1000.0;
  a.brainMask = brainMaskOf(colin.brain, a.G);
  const float* intensity = a.intensity();
  const float maxIntensity = *std::max_element(intensity, intensity + a.N);
  a.headMask = headMaskOf(intensity, maxIntensity, a.brain(), a.G);
  a.tissue = tissueMeansOf(intensity, maxIntensity, a.brain(), a.N);
  a.brainDistance = signedDistanceMm(a.brainMask);
  a.brainCentroid = centroidOf(a.G, a.brain());
  a.ventricleMask = ventricleMaskOf(a);
  return a;
}

/// The tumour: an irregular ellipsoid, its surface bent by six seeded harmonics.
struct TumourShape {
  Vec3 centre{}, axis{}, e1{}, e2{};
  Vec3 semiAxes{13.0, 10.5, 10.0};
  double harmonics[6]{};

  /// The ellipsoidal radius of `p`, < 1 inside.
  double radiusAt(const Vec3& p) const
  {
    const Vec3 d = p - centre;
    const Vec3 local{dot(d, e1) / semiAxes[0], dot(d, e2) / semiAxes[1], dot(d, axis) / semiAxes[2]};
    const double rho = norm(local);
    if (rho < 1e-9) return 0.0;
    const double theta = std::acos(std::clamp(local[2] / rho, -1.0, 1.0)), phi = std::atan2(local[1], local[0]);
    const double bump = harmonics[0] * std::cos(2 * phi) + harmonics[1] * std::sin(3 * phi) +
                        harmonics[2] * std::cos(2 * theta) + harmonics[3] * std::sin(theta) * std::cos(phi) +
                        harmonics[4] * std::cos(3 * theta) + harmonics[5] * std::sin(2 * phi) * std::sin(theta);
    return rho / (1.0 + bump);
  }
  double meanSemiAxis() const { return (semiAxes[0] + semiAxes[1] + semiAxes[2]) / 3.0; }
};

/// The surgery: the craniotomy, the widths of the subsidence under it, and the tumour below it.
struct Surgery {
  Vec3 axis{}, craniotomyCentre{};
  double lateralSigma = 25.0, decayLength = 35.0, openingRadius = 30.0;
  TumourShape tumour;
};

/// The craniotomy where the outward ray from the brain's centroid leaves the brain; the tumour
/// P.tumourDepthMm below it (22 mm by default), with a T1 post-contrast look (hypointense core,
/// enhancing rim).
Surgery plannedSurgery(const CaseParameters& P, const Anatomy& a, std::mt19937_64& rng)
{
  Surgery s;
  const Vec3 axis = craniotomyDirection(P.craniotomy);
  s.axis = axis;
  s.craniotomyCentre = a.brainCentroid;
  for (double t = 0; t < 150; t += 0.25) {
    const Vec3 p = a.brainCentroid + t * axis;
    if (sampleNearest<unsigned char>(a.G, a.brain(), p, 0)) s.craniotomyCentre = p;
  }
  TumourShape& tumour = s.tumour;
  tumour.centre = s.craniotomyCentre - P.tumourDepthMm * axis;
  tumour.axis = axis;
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (double& h : tumour.harmonics) h = 0.1 * uniform(rng);
  const Vec3 e1 = normalized({-axis[1], axis[0], 0.0 + 1e-9});
  tumour.e1 = e1;
  tumour.e2 = {axis[1] * e1[2] - axis[2] * e1[1], axis[2] * e1[0] - axis[0] * e1[2], axis[0] * e1[1] - axis[1] * e1[0]};
  return s;
}

/// The preoperative T1 inside the tumour (`texture` about 1 gives it a grain).
double tumourIntensity(TumourAppearance appearance, double rho, double texture, const TissueMeans& tissue)
{
  const double whiteMean = tissue.white, greyMean = tissue.grey;
  switch (appearance) {
  case TumourAppearance::RimEnhancing: {
    const double rim = std::clamp((rho - 0.7) / 0.15, 0.0, 1.0);
    return texture * (0.45 * whiteMean + rim * (1.1 - 0.45) * whiteMean);
  }
  case TumourAppearance::Hypointense: return texture * 0.5 * whiteMean;
  case TumourAppearance::NearlyIsointense: return texture * 0.95 * 0.5 * (greyMean + whiteMean);
  }
  return 0;
}

/// The preoperative labels and image: the template's anatomy with the tumour painted in.
void paintPreoperativeCase(const CaseParameters& P, const Anatomy& a, const TumourShape& tumour, SimulatedCase& result)
{
  result.preopLabels = newImage<LabelImage>(a.G, Background);
  result.preopImage = newImage<ScalarImage>(a.G, 0.0f);
  LabelPixel* labels = result.preopLabels->GetBufferPointer();
  float* preop = result.preopImage->GetBufferPointer();
  const unsigned char *brain = a.brain(), *head = a.head(), *ventricles = a.ventricles();
  const float *intensity = a.intensity(), *brainDepth = a.brainDepth();
  const double meanAxis = tumour.meanSemiAxis();
  parallelFor(a.N, [&](std::size_t i) {
    const Vec3 p = a.G.pointOf(i);
    LabelPixel label = brain[i] ? Parenchyma : head[i] ? Head : Background;
    if (brain[i] && ventricles[i]) label = Ventricles;
    double value = intensity[i];
    if (brain[i] && brainDepth[i] <= -3.0f) {
      const double rho = tumour.radiusAt(p);
      // Partial volume over about 1 mm at the tumour's edge.
      const double alpha = std::clamp(0.5 + (1.0 - rho) * meanAxis / 1.0, 0.0, 1.0);
      if (alpha > 0) {
        const double texture = 1.0 + 0.05 * (2.0 * hashUniform(P.seed, i) - 1.0);
        const double tumourValue = tumourIntensity(P.tumourAppearance, rho, texture, a.tissue);
        value = (1 - alpha) * value + alpha * tumourValue;
      }
      if (rho <= 1.0) label = Tumour;
    }
    labels[i] = label;
    preop[i] = float(value);
  });
}

/// A point of the cortex: where the ray from the brain's centroid along `direction` leaves the
/// brain, 6 mm deep.
Vec3 corticalPoint(const Anatomy& a, const Vec3& direction)
{
  Vec3 surface = a.brainCentroid;
  for (double s = 0; s < 150; s += 0.5) {
    const Vec3 p = a.brainCentroid + s * direction;
    if (sampleNearest<unsigned char>(a.G, a.brain(), p, 0)) surface = p;
  }
  return surface - 6.0 * direction;
}

/// fMRI: a t-map on a 3 mm grid, two activations near the tumour and one deactivation, in noise.
ScalarImage::Pointer simulatedFmri(const Anatomy& a, const Vec3& axis, std::mt19937_64& rng)
{
  const Grid& G = a.G;
  Grid F = G;
  const Vec3 extent{G.spacing[0] * G.size[0], G.spacing[1] * G.size[1], G.spacing[2] * G.size[2]};
  for (int i = 0; i < 3; ++i) {
    F.spacing[i] = 3.0;
    F.size[i] = std::size_t(std::ceil(extent[i] / 3.0));
  }
  F.origin = G.point(-0.5 + 1.5 / G.spacing[0], -0.5 + 1.5 / G.spacing[1], -0.5 + 1.5 / G.spacing[2]);
  ScalarImage::Pointer fmri = newImage<ScalarImage>(F, 0.0f);
  float* t = fmri->GetBufferPointer();
  // Cortical points in directions tilted from the craniotomy axis.
  const Vec3 motor = corticalPoint(a, normalized(axis + Vec3{0, 0.45, 0.1}));
  const Vec3 language = corticalPoint(a, normalized(axis + Vec3{0, -0.2, -0.45}));
  const Vec3 deactivation = corticalPoint(a, normalized(Vec3{-axis[0], 0.8, 0.3}));
  struct Blob { Vec3 centre; double peak, sigma; };
  const Blob blobs[] = {{motor, 9.0, 5.0}, {language, 6.5, 4.0}, {deactivation, -4.5, 6.0}};
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::vector<double> noise(F.count());
  for (double& v : noise) v = gauss(rng);
  for (std::size_t i = 0; i < F.count(); ++i) {
    const Vec3 p = F.pointOf(i);
    if (!sampleNearest<unsigned char>(G, a.brain(), p, 0)) continue;
    double value = 0.8 * noise[i];
    for (const Blob& b : blobs) {
      const double d = norm(p - b.centre);
      value += b.peak * std::exp(-d * d / (2 * b.sigma * b.sigma));
    }
    t[i] = float(value);
  }
  return fmri;
}

/// The true subsidence field w on its own grid (double vectors): tissue at x' came from x' + w(x').
struct Subsidence {
  Grid W;
  DoubleField::Pointer field;

  const itk::Vector<double, 3>* w() const { return field->GetBufferPointer(); }
  Vec3 at(const Vec3& p) const { return sampleField(W, w(), p); }
};

/// The analytic model of the kinematic truth: the sinking at `p`, outward along the axis.
double kinematicSinking(const CaseParameters& P, const Surgery& s, const Vec3& p)
{
  const Vec3 d = p - s.craniotomyCentre;
  const double along = dot(d, s.axis);
  const double depth = -along; // below the preoperative surface point
  const double r2 = dot(d, d) - along * along;
  const double subsidence = P.shiftMillimetres * std::exp(-r2 / (2 * s.lateralSigma * s.lateralSigma));
  return subsidence * std::exp(-std::max(depth - subsidence, 0.0) / s.decayLength);
}

/// The subsidence field w on a 4 mm grid over the preoperative field of view: smooth on the scale of
/// its 25 mm profile, and small enough to keep in the truth transform file. Kinematic, or from the
/// finite element truth (whose figures go into `figures`).
Subsidence trueSubsidence(const CaseParameters& P, bool small, const Grid& G, const Surgery& s, const LabelImage& preopLabels,
                          CaseFigures& figures)
{
  Subsidence result;
  Grid& W = result.W;
  W = G;
  const Vec3 extent{G.spacing[0] * (G.size[0] - 1), G.spacing[1] * (G.size[1] - 1), G.spacing[2] * (G.size[2] - 1)};
  for (int i = 0; i < 3; ++i) {
    W.spacing[i] = 4.0;
    W.size[i] = std::size_t(std::ceil(extent[i] / 4.0)) + 1;
  }
  W.origin = G.origin;
  result.field = DoubleField::New();
  W.applyTo(result.field.GetPointer());
  itk::Vector<double, 3>* w = result.field->GetBufferPointer();
  if (P.truth == TruthModel::Kinematic) {
    for (std::size_t i = 0; i < W.count(); ++i) {
      const double sinking = kinematicSinking(P, s, W.pointOf(i));
      for (int k = 0; k < 3; ++k) w[i][k] = sinking * s.axis[k];
    }
    return result;
  }
  FiniteElementTruthParameters fe;
  fe.craniotomyCentre = s.craniotomyCentre;
  fe.craniotomyAxis = s.axis;
  fe.shiftMm = P.shiftMillimetres;
  fe.lateralSigmaMm = s.lateralSigma;
  fe.openingRadiusMm = s.openingRadius;
  fe.seed = P.seed;
  if (small) fe.elementSizeMm = 10.0;
  const FiniteElementTruthFigures f = solveFiniteElementTruth(preopLabels, *result.field, fe);
  figures.truthNodes = f.nodes;
  figures.truthElements = f.elements;
  figures.truthFoldedElements = f.invertedElements;
  figures.truthSolverSeconds = f.ccxSeconds;
  return result;
}

/// The deformed configuration on the preoperative grid.
struct DeformedConfiguration {
  LabelImage::Pointer labels;
  ScalarImage::Pointer image;
  /// What each voxel of the preoperative brain holds now: tissue, the gap the brain sank away from,
  /// or the resection cavity (both intraoperative-only matter, label 0 in the truth).
  std::vector<unsigned char> matter;
};

/// The tissue moved by the subsidence, the resected tumour removed and the bone flap opened; the
/// gap and the cavity still empty.
DeformedConfiguration movedTissue(const CaseParameters& P, const Anatomy& a, const Surgery& s, const Subsidence& subsidence,
                                  const SimulatedCase& result)
{
  const Grid& G = a.G;
  DeformedConfiguration deformed;
  deformed.labels = newImage<LabelImage>(G, Background);
  deformed.image = newImage<ScalarImage>(G, 0.0f);
  deformed.matter.assign(a.N, Outside);
  LabelPixel* dLabels = deformed.labels->GetBufferPointer();
  float* dImage = deformed.image->GetBufferPointer();
  std::vector<unsigned char>& matter = deformed.matter;
  const LabelPixel* labels = result.preopLabels->GetBufferPointer();
  const float* preop = result.preopImage->GetBufferPointer();
  const unsigned char *brain = a.brain(), *head = a.head();
  parallelFor(a.N, [&](std::size_t i) {
    const Vec3 p = G.pointOf(i);
    if (brain[i]) {
      const Vec3 source = p + subsidence.at(p);
      const LabelPixel sourceLabel = sampleNearest<LabelPixel>(G, labels, source, Background);
      if (sourceLabel >= Parenchyma) {
        dLabels[i] = sourceLabel;
        dImage[i] = float(sampleLinear(G, preop, source, 0.0));
        matter[i] = Tissue;
      } else {
        matter[i] = Gap;
      }
      if (P.resection && dLabels[i] == Tumour) {
        dLabels[i] = Background;
        matter[i] = Cavity;
      }
      return;
    }
    const Vec3 d = p - s.craniotomyCentre;
    const double along = dot(d, s.axis);
    if (head[i] && along > 0 && dot(d, d) - along * along < s.openingRadius * s.openingRadius) {
      dLabels[i] = Background; // the bone flap and scalp are open
      dImage[i] = 0.0f;
      return;
    }
    dLabels[i] = labels[i];
    dImage[i] = preop[i];
  });
  return deformed;
}

/// The fluid under the craniotomy and in the cavity is CSF and saline: as dark as the ventricles'
/// CSF (the built-in case's dark gap and cavity keep their historical value, the CSF class mean).
double fluidIntensity(const CaseParameters& P, const Anatomy& a, const SimulatedCase& result)
{
  double fluidValue = a.tissue.csf;
  if (P.gap == GapContent::FluidAndAir) {
    const LabelPixel* labels = result.preopLabels->GetBufferPointer();
    const float* preop = result.preopImage->GetBufferPointer();
    std::vector<float> ventricular;
    for (std::size_t i = 0; i < a.N; ++i) {
      if (labels[i] == Ventricles) ventricular.push_back(preop[i]);
    }
    if (!ventricular.empty()) {
      std::nth_element(ventricular.begin(), ventricular.begin() + std::ptrdiff_t(ventricular.size() / 2), ventricular.end());
      fluidValue = ventricular[ventricular.size() / 2];
    }
  }
  return fluidValue;
}

/// The deformed configuration with its intraoperative-only matter (gap, cavity) and, after
/// gadolinium, its enhancement.
DeformedConfiguration deformedConfiguration(const CaseParameters& P, const Anatomy& a, const Surgery& s,
                                            const Subsidence& subsidence, SimulatedCase& result)
{
  DeformedConfiguration deformed = movedTissue(P, a, s, subsidence, result);
  float* dImage = deformed.image->GetBufferPointer();
  const double fluidValue = fluidIntensity(P, a, result);
  fillIntraoperativeMatter(P, a.G, s.axis, fluidValue, a.tissue.white, deformed.matter, dImage, result.figures);
  if (P.contrast == IntraopContrast::T1PostContrast) {
    enhanceAfterContrastAgent(a.G, deformed.matter, deformed.labels->GetBufferPointer(), a.brainDepth(), s.craniotomyCentre,
                              s.axis, s.openingRadius, a.tissue.white, dImage);
  }
  return deformed;
}

/// The patient in the scanner: intraoperative point y = M(x'), rotated about the head's centre.
Euler::Pointer patientMotion(const CaseParameters& P, const Anatomy& a)
{
  auto motion = Euler::New();
  const Vec3 headCentre = centroidOf(a.G, a.head());
  Euler::CenterType centre;
  Euler::OutputVectorType translation;
  for (int k = 0; k < 3; ++k) {
    centre[k] = headCentre[k];
    translation[k] = P.translationMillimetres[k];
  }
  motion->SetCenter(centre);
  const double toRadians = M_PI / 180.0;
  motion->SetRotation(P.rotationDegrees[0] * toRadians, P.rotationDegrees[1] * toRadians, P.rotationDegrees[2] * toRadians);
  motion->SetTranslation(translation);
  return motion;
}

/// The truth maps y back: first the inverse of the motion (returned), then the subsidence field.
Euler::Pointer setTruthTransforms(const Euler& motion, const Subsidence& subsidence, SimulatedCase& result)
{
  auto rigid = Euler::New();
  motion.GetInverse(rigid);
  result.rigidIntraopToPreop = rigid.GetPointer();
  auto composite = itk::CompositeTransform<double, 3>::New();
  auto fieldTransform = itk::DisplacementFieldTransform<double, 3>::New();
  fieldTransform->SetDisplacementField(subsidence.field);
  composite->AddTransform(fieldTransform); // applied second
  composite->AddTransform(rigid);          // applied first
  result.intraopToPreop = composite.GetPointer();
  return rigid;
}

/// The intraoperative grid: axial, centred on the moved brain; a slab centred between the
/// craniotomy and the tumour when asked.
Grid intraoperativeGrid(const CaseParameters& P, bool small, const Euler& motion, const Anatomy& a, const Surgery& s)
{
  Grid I;
  I.size = small ? std::array<std::size_t, 3>{96, 96, 30} : std::array<std::size_t, 3>{256, 256, 60};
  I.spacing = small ? Vec3{2.5, 2.5, 5.0} : Vec3{0.9375, 0.9375, 2.5};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) I.direction[r][c] = r == c ? 1.0 : 0.0;
  }
  const Vec3 centre = toVec(motion.TransformPoint(toPoint(a.brainCentroid + Vec3{0, 0, 10})));
  for (int k = 0; k < 3; ++k) I.origin[k] = centre[k] - 0.5 * I.spacing[k] * (I.size[k] - 1);
  if (P.fieldOfView == FieldOfView::Slab) {
    const Vec3 middle = toVec(motion.TransformPoint(toPoint(0.5 * (s.craniotomyCentre + s.tumour.centre))));
    cutToSlab(I, middle[2], small);
  }
  return I;
}

/// The bias field: exp(strength * q) with q a random quadratic over the field of view, |q| <= 1.
struct BiasField {
  double coefficients[9]{};
  double scale = 1e-12; ///< the largest |quadratic| over the field of view

  double quadratic(const Vec3& u) const
  {
    const double terms[9] = {u[0], u[1], u[2], u[0] * u[0], u[1] * u[1], u[2] * u[2], u[0] * u[1], u[0] * u[2], u[1] * u[2]};
    double q = 0;
    for (int k = 0; k < 9; ++k) q += coefficients[k] * terms[k];
    return q;
  }
};

BiasField randomBiasField(std::mt19937_64& rng)
{
  BiasField bias;
  std::normal_distribution<double> gauss(0.0, 1.0);
  for (double& c : bias.coefficients) c = gauss(rng);
  for (int a = -4; a <= 4; ++a) {
    for (int b = -4; b <= 4; ++b) {
      for (int c = -4; c <= 4; ++c) bias.scale = std::max(bias.scale, std::abs(bias.quadratic({a / 4.0, b / 4.0, c / 4.0})));
    }
  }
  return bias;
}

/// The intraoperative scan of the deformed configuration seen through the rigid truth, and its true
/// labels; another scanner with another contrast and a bias field, before noise.
void scanIntraoperative(const CaseParameters& P, const Anatomy& a, const DeformedConfiguration& deformedCase, const Euler& rigid,
                        const Grid& I, std::mt19937_64& rng, SimulatedCase& result)
{
  result.intraopImage = newImage<ScalarImage>(I, 0.0f);
  result.intraopLabels = newImage<LabelImage>(I, Background);
  float* intraop = result.intraopImage->GetBufferPointer();
  LabelPixel* intraopLabels = result.intraopLabels->GetBufferPointer();
  const BiasField biasField = randomBiasField(rng);
  auto rigidPoint = [&](const Vec3& y) { return toVec(rigid.TransformPoint(toPoint(y))); };
  const Grid& Gd = a.G;
  const float* deformed = deformedCase.image->GetBufferPointer();
  const LabelPixel* dLabels = deformedCase.labels->GetBufferPointer();
  const double whiteMean = a.tissue.white;
  const IntensityMap contrast = intraopContrastMap(P.contrast, a.tissue.csf / whiteMean, a.tissue.grey / whiteMean);
  parallelFor(I.count(), [&](std::size_t i) {
    const auto idx = I.indexOf(i);
    double sum = 0;
    // The slice profile: three samples across the slice thickness.
    for (double dz : {-1.0 / 3.0, 0.0, 1.0 / 3.0}) {
      const Vec3 y = I.point(double(idx[0]), double(idx[1]), double(idx[2]) + dz);
      sum += sampleLinear(Gd, deformed, rigidPoint(y), 0.0);
    }
    const Vec3 y = I.point(double(idx[0]), double(idx[1]), double(idx[2]));
    intraopLabels[i] = sampleNearest<LabelPixel>(Gd, dLabels, rigidPoint(y), Background);
    // Another scanner, another contrast: a gamma on the white-matter-normalised intensity.
    const double normalisedValue = std::max(sum / 3.0, 0.0) / whiteMean;
    const Vec3 u{2.0 * idx[0] / (I.size[0] - 1) - 1.0, 2.0 * idx[1] / (I.size[1] - 1) - 1.0,
                 2.0 * idx[2] / (I.size[2] - 1) - 1.0};
    const double bias = std::exp(P.biasStrength * biasField.quadratic(u) / biasField.scale);
    intraop[i] = float(1000.0 * contrast(normalisedValue) * bias);
  });
}

/// Rician noise, drawn in voxel order from the seeded generator.
void addRicianNoise(double noiseFraction, std::mt19937_64& rng, ScalarImage* image)
{
  float* intraop = image->GetBufferPointer();
  std::normal_distribution<double> gauss(0.0, noiseFraction * 1000.0);
  for (std::size_t i = 0, n = image->GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) {
    const double real = intraop[i] + gauss(rng), imaginary = gauss(rng);
    intraop[i] = float(std::round(std::sqrt(real * real + imaginary * imaginary)));
  }
}

/// Whether the intraoperative grid holds the point x' of the deformed configuration once moved,
/// at least `marginMm` from its edges.
bool insideIntraopView(const Grid& I, const Euler& motion, const Vec3& xPrime, double marginMm)
{
  const Vec3 c = I.continuousIndex(toVec(motion.TransformPoint(toPoint(xPrime))));
  for (int k = 0; k < 3; ++k) {
    const double margin = marginMm / I.spacing[k];
    if (c[k] < margin || c[k] > double(I.size[k] - 1) - margin) return false;
  }
  return true;
}

/// The volumes and displacements of case.json: the tumour, ventricles, brain, gap and cavity, the
/// brain the intraoperative grid sees and the largest displacement of the deformed brain.
void measureVolumes(const Anatomy& a, const SimulatedCase& result, const DeformedConfiguration& deformed,
                    const Subsidence& subsidence, const Euler& motion, const Grid& I, CaseFigures& figures)
{
  const Grid& G = a.G;
  const double voxelMl = a.voxelMl;
  const LabelPixel* labels = result.preopLabels->GetBufferPointer();
  const LabelPixel* dLabels = deformed.labels->GetBufferPointer();
  const unsigned char* brain = a.brain();
  for (std::size_t i = 0; i < a.N; ++i) {
    if (labels[i] == Tumour) figures.tumourVolumeMl += voxelMl;
    if (labels[i] == Ventricles) figures.ventricleVolumeMl += voxelMl;
    if (labels[i] >= Parenchyma) figures.brainVolumeMl += voxelMl;
    if (brain[i] && dLabels[i] == Background) {
      const Vec3 source = G.pointOf(i) + subsidence.at(G.pointOf(i));
      if (sampleNearest<LabelPixel>(G, labels, source, Background) == Tumour) figures.cavityVolumeMl += voxelMl;
      else figures.gapVolumeMl += voxelMl;
    }
    if (dLabels[i] >= Parenchyma) {
      const Vec3 c = I.continuousIndex(toVec(motion.TransformPoint(toPoint(G.pointOf(i)))));
      bool inView = true;
      for (int k = 0; k < 3; ++k) inView = inView && c[k] >= -0.5 && c[k] <= double(I.size[k]) - 0.5;
      if (inView) figures.brainInFieldOfViewMl += voxelMl;
    }
    if (dLabels[i] >= Parenchyma) figures.maxBrainDisplacementMm = std::max(figures.maxBrainDisplacementMm, norm(subsidence.at(G.pointOf(i))));
  }
}

/// The smallest Jacobian determinant of x' -> x' + w(x') at the subsidence grid's inner nodes in
/// the brain; 1 at most.
double minimumJacobianDeterminant(const Subsidence& subsidence, const Anatomy& a)
{
  const Grid& W = subsidence.W;
  const itk::Vector<double, 3>* w = subsidence.w();
  double minimum = 1.0;
  for (std::size_t k = 1; k + 1 < W.size[2]; ++k) {
    for (std::size_t j = 1; j + 1 < W.size[1]; ++j) {
      for (std::size_t i = 1; i + 1 < W.size[0]; ++i) {
        const Vec3 p = W.point(double(i), double(j), double(k));
        if (!sampleNearest<unsigned char>(a.G, a.brain(), p, 0)) continue;
        // J = I + grad w, by central differences along the grid axes (the grid is axis-aligned
        // with the preoperative image, whose direction is a signed permutation here).
        double J[3][3];
        const std::size_t o[3][2] = {{W.offset(i + 1, j, k), W.offset(i - 1, j, k)},
                                     {W.offset(i, j + 1, k), W.offset(i, j - 1, k)},
                                     {W.offset(i, j, k + 1), W.offset(i, j, k - 1)}};
        double gradIndex[3][3]; // d w_r / d index_c
        for (int c = 0; c < 3; ++c) {
          for (int r = 0; r < 3; ++r) gradIndex[r][c] = (w[o[c][0]][r] - w[o[c][1]][r]) / (2.0 * W.spacing[c]);
        }
        for (int r = 0; r < 3; ++r) {
          for (int c = 0; c < 3; ++c) {
            double g = 0; // d w_r / d x_c = sum_m gradIndex[r][m] * direction[c][m]
            for (int m = 0; m < 3; ++m) g += gradIndex[r][m] * W.direction[c][m];
            J[r][c] = (r == c ? 1.0 : 0.0) + g;
          }
        }
        const double det = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) - J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
                           J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
        minimum = std::min(minimum, det);
      }
    }
  }
  return minimum;
}

/// The voxel centres x' of the deformed configuration where landmarks may go, by region.
struct LandmarkCandidates {
  std::vector<Vec3> craniotomy, cavity, margin, brain, head;
};

/// Deformed brain at least 3 mm deep and inside the intraoperative view (8 mm from its edges): near
/// the cavity (10 mm), at a tumour's margin (8 mm either side: where the surgeon looks), under the
/// craniotomy, or elsewhere; and head that did not move.
LandmarkCandidates landmarkCandidates(const Anatomy& a, const Surgery& s, const SimulatedCase& result,
                                      const DeformedConfiguration& deformed, const Subsidence& subsidence, const Euler& motion,
                                      const Grid& I)
{
  const Grid& G = a.G;
  const LabelPixel* labels = result.preopLabels->GetBufferPointer();
  const LabelPixel* dLabels = deformed.labels->GetBufferPointer();
  const unsigned char* brain = a.brain();
  auto deformedBrainMask = newImage<MaskImage>(G, 0);
  auto cavityMask = newImage<MaskImage>(G, 0);
  auto tumourMask = newImage<MaskImage>(G, 0);
  bool hasTumour = false;
  for (std::size_t i = 0; i < a.N; ++i) {
    deformedBrainMask->GetBufferPointer()[i] = dLabels[i] >= Parenchyma;
    cavityMask->GetBufferPointer()[i] = brain[i] && dLabels[i] == Background && labels[i] != Head &&
                                        sampleNearest<LabelPixel>(G, labels, G.pointOf(i) + subsidence.at(G.pointOf(i)), 0) == Tumour;
    tumourMask->GetBufferPointer()[i] = dLabels[i] == Tumour;
    hasTumour = hasTumour || dLabels[i] == Tumour;
  }
  ScalarImage::Pointer tissueDepth = signedDistanceMm(deformedBrainMask);
  ScalarImage::Pointer cavityDistance = signedDistanceMm(cavityMask);
  const bool hasCavity = result.figures.cavityVolumeMl > 0;
  ScalarImage::Pointer tumourDistance = hasTumour ? signedDistanceMm(tumourMask) : nullptr;
  LandmarkCandidates candidates;
  for (std::size_t i = 0; i < a.N; ++i) {
    const LabelPixel l = dLabels[i];
    const Vec3 p = G.pointOf(i);
    if (l >= Parenchyma && tissueDepth->GetBufferPointer()[i] <= -3.0f) {
      if (!insideIntraopView(I, motion, p, 8.0)) continue;
      const Vec3 d = p - s.craniotomyCentre;
      const double along = dot(d, s.axis);
      const double r = std::sqrt(std::max(dot(d, d) - along * along, 0.0));
      if (hasCavity && cavityDistance->GetBufferPointer()[i] <= 10.0f) candidates.cavity.push_back(p);
      else if (tumourDistance && std::abs(tumourDistance->GetBufferPointer()[i]) <= 8.0f) candidates.margin.push_back(p);
      else if (r < s.lateralSigma && -along < 35.0) candidates.craniotomy.push_back(p);
      else candidates.brain.push_back(p);
    } else if (l == Head && norm(subsidence.at(p)) < 0.01 && insideIntraopView(I, motion, p, 8.0)) {
      candidates.head.push_back(p);
    }
  }
  return candidates;
}

/// Landmarks, chosen in the deformed configuration x' (voxel centres), seen at y = M(x'), apart
/// from each other, in random (seeded) order.
void chooseLandmarks(const LandmarkCandidates& candidates, bool small, const Euler& motion, std::mt19937_64& rng,
                     SimulatedCase& result)
{
  const bool hasCavity = result.figures.cavityVolumeMl > 0;
  std::vector<Vec3> taken;
  const double separation = small ? 10.0 : 8.0;
  const auto craniotomyPoints = pickSeparated(candidates.craniotomy, 10, separation, taken, rng);
  const auto cavityPoints = pickSeparated(candidates.cavity, hasCavity ? 6 : 0, 6.0, taken, rng);
  const auto marginPoints = pickSeparated(candidates.margin, 6, 6.0, taken, rng);
  const auto brainPoints = pickSeparated(candidates.brain, 20, 15.0, taken, rng);
  const auto headPoints = pickSeparated(candidates.head, 10, 25.0, taken, rng);
  auto add = [&](const std::vector<Vec3>& points, const std::string& prefix, bool moves) {
    int number = 1;
    for (const Vec3& xPrime : points) {
      LandmarkPair pair;
      char name[64];
      std::snprintf(name, sizeof(name), "%s-%02d", prefix.c_str(), number++);
      pair.name = name;
      pair.intraop = motion.TransformPoint(toPoint(xPrime));
      // Brain tissue came from x' + w(x'); the head did not move.
      pair.preop = moves ? result.intraopToPreop->TransformPoint(pair.intraop) : toPoint(xPrime);
      result.landmarks.push_back(pair);
    }
  };
  add(craniotomyPoints, "craniotomy", true);
  add(cavityPoints, "near-cavity", true);
  add(marginPoints, "tumour-margin", true);
  add(brainPoints, "brain", true);
  add(headPoints, "head", false);
}

} // namespace

SimulatedCase simulateCase(const CaseParameters& P)
{
  P.validate();
  const bool small = P.size == CaseSize::Small;
  const Anatomy anatomy = preoperativeAnatomy(P, small);
  std::mt19937_64 rng(P.seed);
  SimulatedCase result;
  CaseFigures& figures = result.figures;

  // The preoperative case; then the truth of the shift and the deformed configuration x'.
  const Surgery surgery = plannedSurgery(P, anatomy, rng);
  paintPreoperativeCase(P, anatomy, surgery.tumour, result);
  result.preopFmri = simulatedFmri(anatomy, surgery.axis, rng);
  const Subsidence subsidence = trueSubsidence(P, small, anatomy.G, surgery, *result.preopLabels, figures);
  const DeformedConfiguration deformed = deformedConfiguration(P, anatomy, surgery, subsidence, result);

  // The patient in the scanner: intraop point y = M(x'); the truth maps y back.
  const Euler::Pointer motion = patientMotion(P, anatomy);
  const Euler::Pointer rigid = setTruthTransforms(*motion, subsidence, result);
  const Grid I = intraoperativeGrid(P, small, *motion, anatomy, surgery);
  scanIntraoperative(P, anatomy, deformed, *rigid, I, rng, result);
  addRicianNoise(P.noiseFraction, rng, result.intraopImage);

  figures.craniotomyCentre = toPoint(surgery.craniotomyCentre);
  figures.craniotomyAxis = surgery.axis;
  figures.tumourCentre = toPoint(surgery.tumour.centre);
  figures.decayLengthMm = surgery.decayLength;
  figures.lateralSigmaMm = surgery.lateralSigma;
  measureVolumes(anatomy, result, deformed, subsidence, *motion, I, figures);
  figures.minJacobianDeterminant = minimumJacobianDeterminant(subsidence, anatomy);

  const LandmarkCandidates candidates = landmarkCandidates(anatomy, surgery, result, deformed, subsidence, *motion, I);
  chooseLandmarks(candidates, small, *motion, rng, result);
  return result;
}

std::optional<std::string> foldedTruthWarning(const CaseFigures& f)
{
  if (f.minJacobianDeterminant > 0) return std::nullopt; // elements a linear solve inverted, but a field that does not fold
  std::string what = "its Jacobian determinant down to " + numberText(f.minJacobianDeterminant) + " in the brain";
  if (f.truthFoldedElements > 0) {
    what += ", " + std::to_string(f.truthFoldedElements) + " of its " + std::to_string(f.truthElements) + " finite elements inverted";
  }
  return "case: the truth folds (" + what + "): where it folds it is ill-defined, the inverted field carrying preoperative brain "
         "where there is none (pieces of brain in the gap), and the figures against it there (TRE, the boundary under the "
         "craniotomy) measure the fold as well as the update";
}

void writeCase(const SimulatedCase& simulated, const CaseParameters& P, const fs::path& folder)
{
  const CaseFiles files(folder);
  writeScalarVolume(simulated.preopImage, files.preopImage);
  writeLabelVolume(simulated.preopLabels, files.preopLabels);
  writeScalarVolume(simulated.preopFmri, files.preopFmri);
  writeScalarVolume(simulated.intraopImage, files.intraopImage, StoredPixelType::Int16);
  writeLabelVolume(simulated.intraopLabels, files.truthIntraopLabels);
  writeTransform(simulated.intraopToPreop, files.truthTransform);
  writeTransform(simulated.rigidIntraopToPreop, files.truthRigidTransform);
  writeLandmarksCsv(simulated.landmarks, files.landmarks);

  const CaseFigures& f = simulated.figures;
  const std::optional<std::string> folds = foldedTruthWarning(f);
  auto point = [](const PhysicalPoint& p) { return nlohmann::json::array({p[0], p[1], p[2]}); };
  nlohmann::json description = {
    {"description", "BrainShift built-in case: Colin27 T1 with a simulated brain shift of known truth"},
    {"truth_model",
     "kinematic subsidence under the craniotomy (Gaussian lateral profile, exponential decay with depth), "
     "independent of the finite element solver; defined as the resampling field on the deformed configuration"},
    {"parameters",
     {{"size", P.size == CaseSize::Full ? "full" : "small"},
      {"seed", P.seed},
      {"shift_mm", P.shiftMillimetres},
      {"craniotomy", toString(P.craniotomy)},
      {"resection", P.resection},
      {"rotation_degrees", P.rotationDegrees},
      {"translation_mm", P.translationMillimetres},
      {"noise_fraction", P.noiseFraction},
      {"bias_strength", P.biasStrength},
      {"contrast", toString(P.contrast)},
      {"tumour_appearance", toString(P.tumourAppearance)},
      {"tumour_depth_mm", P.tumourDepthMm},
      {"gap", toString(P.gap)},
      {"gap_fluid_fraction", P.gapFluidFraction},
      {"cavity_fluid_fraction", P.cavityFluidFraction},
      {"gravity_tilt_degrees", P.gravityTiltDegrees},
      {"cavity_rim", P.cavityRim},
      {"truth", toString(P.truth)},
      {"field_of_view", toString(P.fieldOfView)},
      {"template", (P.templateFolder / "ch2.nii.gz").string()}}},
    {"figures",
     {{"craniotomy_centre_lps", point(f.craniotomyCentre)},
      {"craniotomy_axis_lps", f.craniotomyAxis},
      {"tumour_centre_lps", point(f.tumourCentre)},
      {"tumour_volume_ml", f.tumourVolumeMl},
      {"ventricle_volume_ml", f.ventricleVolumeMl},
      {"brain_volume_ml", f.brainVolumeMl},
      {"max_brain_displacement_mm", f.maxBrainDisplacementMm},
      {"gap_volume_ml", f.gapVolumeMl},
      {"cavity_volume_ml", f.cavityVolumeMl},
      {"gap_air_ml", f.gapAirMl},
      {"cavity_air_ml", f.cavityAirMl},
      {"min_jacobian_determinant", f.minJacobianDeterminant},
      {"lateral_sigma_mm", f.lateralSigmaMm},
      {"decay_length_mm", f.decayLengthMm},
      {"truth_nodes", f.truthNodes},
      {"truth_quadratic_elements", f.truthElements},
      {"truth_folded_elements", f.truthFoldedElements},
      {"truth_solver_seconds", f.truthSolverSeconds},
      {"brain_in_field_of_view_ml", f.brainInFieldOfViewMl},
      {"intraop_grid_size", nlohmann::json::array({simulated.intraopImage->GetLargestPossibleRegion().GetSize()[0],
                                                    simulated.intraopImage->GetLargestPossibleRegion().GetSize()[1],
                                                    simulated.intraopImage->GetLargestPossibleRegion().GetSize()[2]})},
      {"landmarks", simulated.landmarks.size()}}},
    {"warnings", folds ? nlohmann::json::array({*folds}) : nlohmann::json::array()},
    {"landmarks",
     "chosen inside the intraoperative field of view only, at least 8 mm from its edges (a pair is one point seen in "
     "both images; with a slab, the brain outside it has none)"},
    {"files",
     {{"preop_image", "preop_image.nii.gz"},
      {"preop_labels", "preop_labels.nii.gz"},
      {"overlays", {{"fmri", "preop_fmri.nii.gz"}}},
      {"intraop_image", "intraop_image.nii.gz"},
      {"landmarks", "landmarks.csv"},
      {"truth_intraop_labels", "truth/intraop_labels.nii.gz"},
      {"truth_intraop_to_preop", "truth/intraop_to_preop.h5"},
      {"truth_rigid_intraop_to_preop", "truth/rigid_intraop_to_preop.tfm"}}}};
  writeTextFileAtomically(files.description, description.dump(2) + "\n");
}

} // namespace brainshift
