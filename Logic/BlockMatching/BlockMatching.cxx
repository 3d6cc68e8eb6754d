#include "BlockMatching.h"

#include "AffineResampling.h"
#include "DistanceMaps.h"
#include "ParallelRanges.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>

namespace brainshift {

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

void requireSensible(const BlockMatchingParameters& p)
{
  auto positive = [](double v) { return std::isfinite(v) && v > 0; };
  if (!positive(p.blockHalfSizeMm) || p.blockHalfSizeMm > 20) throw std::invalid_argument("block matching: the block half-size must be in (0, 20] mm");
  if (!positive(p.blockSpacingMm) || p.blockSpacingMm > 50) throw std::invalid_argument("block matching: the block spacing must be in (0, 50] mm");
  if (!(p.selectedShare > 0 && p.selectedShare <= 1)) throw std::invalid_argument("block matching: the selected share must be in (0, 1]");
  if (!positive(p.searchRadiusMm) || p.searchRadiusMm > 30) throw std::invalid_argument("block matching: the search radius must be in (0, 30] mm");
  if (!positive(p.coarseStepMm)) throw std::invalid_argument("block matching: the coarse step must be positive");
  if (!(p.minimumDepthMm >= 0) || !std::isfinite(p.minimumDepthMm)) throw std::invalid_argument("block matching: the minimum depth must be >= 0 mm");
  if (!(p.minimumSimilarity >= -1 && p.minimumSimilarity <= 1)) throw std::invalid_argument("block matching: the minimum similarity must be in [-1, 1]");
  if (!(p.minimumBrainShare >= 0 && p.minimumBrainShare <= 1)) throw std::invalid_argument("block matching: the minimum brain share must be in [0, 1]");
  if (!positive(p.gridSpacingMm) || p.gridSpacingMm > 10) throw std::invalid_argument("block matching: the grid spacing must be in (0, 10] mm");
  if (p.maximumBlocks == 0) throw std::invalid_argument("block matching: at least one block");
  if (!(p.smoothingMm == 0 || (p.smoothingMm >= 0.1 && p.smoothingMm <= 5))) {
    throw std::invalid_argument("block matching: the smoothing sigma must be 0 (none) or in [0.1, 5] mm");
  }
  if (!(p.selectionCellMm == 0 || (p.selectionCellMm >= 1 && p.selectionCellMm <= 200))) {
    throw std::invalid_argument("block matching: the selection's cell must be 0 (by structure alone) or in [1, 200] mm");
  }
  if (!(p.largestPredictedMm >= 0) || p.largestPredictedMm > 200) throw std::invalid_argument("block matching: the largest predicted displacement must be in [0, 200] mm");
}

/// A volume on the matching grid, x fastest.
template <class T>
struct Volume {
  std::array<int, 3> size{};
  std::vector<T> values;
  std::size_t at(int i, int j, int k) const { return std::size_t(i) + std::size_t(size[0]) * (std::size_t(j) + std::size_t(size[1]) * std::size_t(k)); }
  bool inside(int i, int j, int k, int h) const
  {
    return i - h >= 0 && j - h >= 0 && k - h >= 0 && i + h < size[0] && j + h < size[1] && k + h < size[2];
  }
};

/// The brain's extent in the preoperative image's continuous indices (low > high: no brain). On
/// the image's own grid (the usual case) the labels' index box, else every brain voxel mapped.
void brainExtentInImage(const ScalarImage& preopImage, const LabelImage& preopLabels, const BlockMatchingParameters& p,
                        std::array<double, 3>& low, std::array<double, 3>& high)
{
  low = {1e30, 1e30, 1e30};
  high = {-1e30, -1e30, -1e30};
  const bool sameGrid = ImageGeometry::of(&preopLabels).sameGridAs(ImageGeometry::of(&preopImage));
  const LabelPixel* labels = preopLabels.GetBufferPointer();
  const auto size = preopLabels.GetLargestPossibleRegion().GetSize();
  std::size_t n = 0;
  for (std::size_t k = 0; k < size[2]; ++k) {
    for (std::size_t j = 0; j < size[1]; ++j) {
      for (std::size_t i = 0; i < size[0]; ++i, ++n) {
        if (std::find(p.brainLabels.begin(), p.brainLabels.end(), int(labels[n])) == p.brainLabels.end()) continue;
        std::array<double, 3> index{double(i), double(j), double(k)};
        if (!sameGrid) {
          PhysicalPoint x;
          preopLabels.TransformIndexToPhysicalPoint({{itk::IndexValueType(i), itk::IndexValueType(j), itk::IndexValueType(k)}}, x);
          // In the image's own axes: the grid is aligned with them.
          const auto c = preopImage.TransformPhysicalPointToContinuousIndex<double>(x);
          index = {c[0], c[1], c[2]};
        }
        for (std::size_t d = 0; d < 3; ++d) {
          low[d] = std::min(low[d], index[d]);
          high[d] = std::max(high[d], index[d]);
        }
      }
    }
  }
}

/// The matching grid: the preoperative image's axes, no finer than the grid spacing, over the
/// brain and a margin for the search.
ScalarImage::Pointer matchingGrid(const ScalarImage& preopImage, const LabelImage& preopLabels, const BlockMatchingParameters& p)
{
  std::array<double, 3> low{}, high{};
  brainExtentInImage(preopImage, preopLabels, p, low, high);
  if (low[0] > high[0]) return nullptr; // no brain
  const auto spacing = preopImage.GetSpacing();
  ScalarImage::Pointer grid = ScalarImage::New();
  ScalarImage::SpacingType gridSpacing;
  ScalarImage::SizeType gridSize;
  itk::ContinuousIndex<double, 3> start;
  const double margin = p.searchRadiusMm + p.blockHalfSizeMm + p.largestPredictedMm + 2 * p.gridSpacingMm;
  for (int d = 0; d < 3; ++d) {
    gridSpacing[d] = std::max(spacing[d], p.gridSpacingMm);
    const double lowMm = low[std::size_t(d)] * spacing[d] - margin, highMm = high[std::size_t(d)] * spacing[d] + margin;
    start[d] = lowMm / spacing[d];
    gridSize[d] = itk::SizeValueType(std::ceil((highMm - lowMm) / gridSpacing[d])) + 1;
  }
  PhysicalPoint origin;
  preopImage.TransformContinuousIndexToPhysicalPoint(start, origin);
  grid->SetOrigin(origin);
  grid->SetSpacing(gridSpacing);
  grid->SetDirection(preopImage.GetDirection());
  grid->SetRegions(ScalarImage::RegionType(gridSize));
  return grid;
}

/// `values` (on `grid`, x fastest) as a Volume.
template <class Pixel>
Volume<Pixel> volumeOn(const ScalarImage& grid, std::vector<Pixel> values)
{
  const auto size = grid.GetLargestPossibleRegion().GetSize();
  Volume<Pixel> volume;
  volume.size = {int(size[0]), int(size[1]), int(size[2])};
  volume.values = std::move(values);
  return volume;
}

/// The intraoperative intensity expected given the preoperative one: the conditional mean over
/// the voxels that are brain in both label maps, in 64 bins of the preoperative intensity between
/// its 1st and 99th percentiles (empty bins interpolated). Sets the correlation ratio.
struct IntensityRemap {
  double low = 0, width = 1;
  std::vector<double> table;
  double operator()(double preop) const
  {
    const double position = std::clamp((preop - low) / width - 0.5, 0.0, double(table.size() - 1));
    const std::size_t bin = std::min(std::size_t(position), table.size() - 2);
    const double t = position - double(bin);
    return (1 - t) * table[bin] + t * table[bin + 1];
  }
};

IntensityRemap learnRemap(const Volume<float>& preop, const Volume<float>& intraop, const std::vector<char>& brainInBoth,
                          double& correlationRatio)
{
  std::vector<float> values;
  for (std::size_t n = 0; n < preop.values.size(); ++n) if (brainInBoth[n]) values.push_back(preop.values[n]);
  IntensityRemap remap;
  constexpr std::size_t Bins = 64;
  remap.table.assign(Bins, 0.0);
  correlationRatio = 0;
  if (values.size() < 1000) return remap;
  auto percentile = [&values](double q) {
    const std::size_t k = std::size_t(q * double(values.size() - 1));
    std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(k), values.end());
    return double(values[k]);
  };
  const double lo = percentile(0.01), hi = percentile(0.99);
  remap.low = lo;
  remap.width = std::max(hi - lo, 1e-6) / Bins;
  std::vector<double> sum(Bins, 0), sumSquares(Bins, 0), count(Bins, 0);
  double total = 0, totalSquares = 0, totalCount = 0;
  for (std::size_t n = 0; n < preop.values.size(); ++n) {
    if (!brainInBoth[n]) continue;
    const std::size_t bin = std::size_t(std::clamp((preop.values[n] - lo) / remap.width, 0.0, double(Bins - 1)));
    const double y = intraop.values[n];
    sum[bin] += y;
    sumSquares[bin] += y * y;
    count[bin] += 1;
    total += y;
    totalSquares += y * y;
    totalCount += 1;
  }
  double within = 0;
  for (std::size_t b = 0; b < Bins; ++b) {
    if (count[b] > 0) within += sumSquares[b] - sum[b] * sum[b] / count[b];
  }
  const double variance = totalSquares - total * total / totalCount;
  correlationRatio = variance > 0 ? 1 - within / variance : 0;
  // Bins with too few voxels take their neighbours' values.
  std::vector<std::size_t> filled;
  for (std::size_t b = 0; b < Bins; ++b) {
    if (count[b] >= 20) {
      remap.table[b] = sum[b] / count[b];
      filled.push_back(b);
    }
  }
  if (filled.empty()) return remap;
  for (std::size_t b = 0; b < Bins; ++b) {
    if (count[b] >= 20) continue;
    const auto next = std::lower_bound(filled.begin(), filled.end(), b);
    if (next == filled.begin()) remap.table[b] = remap.table[*next];
    else if (next == filled.end()) remap.table[b] = remap.table[filled.back()];
    else {
      const std::size_t a = *(next - 1), c = *next;
      const double t = double(b - a) / double(c - a);
      remap.table[b] = (1 - t) * remap.table[a] + t * remap.table[c];
    }
  }
  return remap;
}

/// A source block: zero-mean values (each rounded to float, held as a double for the products) and
/// their norm.
struct SourceBlock {
  std::vector<double> values;
  double norm = 0;
};

SourceBlock sourceBlock(const Volume<float>& image, int ci, int cj, int ck, int h)
{
  SourceBlock block;
  double sum = 0;
  for (int k = ck - h; k <= ck + h; ++k)
    for (int j = cj - h; j <= cj + h; ++j)
      for (int i = ci - h; i <= ci + h; ++i) {
        block.values.push_back(image.values[image.at(i, j, k)]);
        sum += image.values[image.at(i, j, k)];
      }
  const double mean = sum / double(block.values.size());
  double squares = 0;
  for (double& v : block.values) {
    v = double(float(v - mean));
    squares += v * v;
  }
  block.norm = std::sqrt(squares);
  return block;
}

/// Sums of `width` consecutive values along a strided line, sliding (one value in, one out):
/// out[k * outStride] = in[k * inStride] + ... + in[(k + width - 1) * inStride], k < outputs.
[[gnu::always_inline]] inline void slidingSums(const double* in, std::size_t inStride, double* out, std::size_t outStride, int outputs,
                                              int width)
{
  double sum = 0;
  for (int t = 0; t < width; ++t) sum += in[std::size_t(t) * inStride];
  for (int k = 0;; ++k) {
    out[std::size_t(k) * outStride] = sum;
    if (k + 1 == outputs) break;
    sum += in[std::size_t(k + width) * inStride] - in[std::size_t(k) * inStride];
  }
}

/// The scan around one block's predicted place, for every offset of the search: the target
/// voxels within reach in doubles, and each offset's window sum and sum of squares by separable box
/// sums, so that an offset's normalised cross-correlation with the source block takes one product
/// per voxel (summed directly, it took three sums and a conversion per voxel: the same matches, their
/// displacements within 1e-11 mm; a later scan's matching of 3,000 blocks 0.50-0.58 -> 0.26-0.29 s).
class SearchWindow {
public:
  SearchWindow(const Volume<float>& target, const std::array<int, 3>& start, int radius, int h)
    : radius_(radius), h_(h), width_(2 * (radius + h) + 1), offsets_(2 * radius + 1)
  {
    const std::size_t w = std::size_t(width_);
    values_.assign(w * w * w, 0.0);
    for (int z = 0; z < width_; ++z)
      for (int y = 0; y < width_; ++y)
        for (int x = 0; x < width_; ++x) {
          const int i = start[0] - radius - h + x, j = start[1] - radius - h + y, k = start[2] - radius - h + z;
          if (i < 0 || j < 0 || k < 0 || i >= target.size[0] || j >= target.size[1] || k >= target.size[2]) continue;
          values_[at(x, y, z)] = target.values[target.at(i, j, k)];
        }
    windowSums();
    const int o = offsets_;
    inside_.resize(sums_.size());
    for (int z = 0; z < o; ++z)
      for (int y = 0; y < o; ++y)
        for (int x = 0; x < o; ++x) {
          inside_[offsetIndex(x, y, z)] = target.inside(start[0] - radius + x, start[1] - radius + y, start[2] - radius + z, h);
        }
  }

  /// The scan as the prediction deforms the block: the window's voxel o (from the block's centre,
  /// in grid voxels) is `target` at start + stretch o (continuous grid indices, trilinear). An
  /// offset whose block reaches a point beyond the grid is outside.
  SearchWindow(const Volume<float>& target, const std::array<double, 3>& start, const std::array<std::array<double, 3>, 3>& stretch,
               int radius, int h)
    : radius_(radius), h_(h), width_(2 * (radius + h) + 1), offsets_(2 * radius + 1)
  {
    const std::size_t w = std::size_t(width_);
    values_.assign(w * w * w, 0.0);
    std::vector<double> beyond(values_.size(), 0.0);
    bool anyBeyond = false;
    const int reach = radius + h;
    for (int z = 0; z < width_; ++z)
      for (int y = 0; y < width_; ++y) {
        double c[3]; // the row's first point, then one step of stretch's first column a voxel
        for (std::size_t a = 0; a < 3; ++a) c[a] = start[a] - stretch[a][0] * reach + stretch[a][1] * (y - reach) + stretch[a][2] * (z - reach);
        for (int x = 0; x < width_; ++x, c[0] += stretch[0][0], c[1] += stretch[1][0], c[2] += stretch[2][0]) {
          if (!trilinear(target, c, values_[at(x, y, z)])) {
            beyond[at(x, y, z)] = 1.0;
            anyBeyond = true;
          }
        }
      }
    windowSums();
    inside_.assign(sums_.size(), 1);
    if (anyBeyond) {
      const std::vector<double> beyondPerOffset = boxSums(beyond);
      for (std::size_t k = 0; k < inside_.size(); ++k) inside_[k] = beyondPerOffset[k] < 0.5;
    }
  }

  /// The correlation of `source` at each of `count` offsets (each within the radius): -2 where the
  /// window leaves the volume or is flat.
  void correlations(const SourceBlock& source, const std::array<int, 3>* offsets, std::size_t count, double* scores) const
  {
    constexpr std::size_t Lanes = 4;
    for (std::size_t first = 0; first < count; first += Lanes) {
      const std::size_t lanes = std::min(Lanes, count - first);
      const double* corner[Lanes];
      double product[Lanes] = {0, 0, 0, 0};
      for (std::size_t m = 0; m < Lanes; ++m) {
        const auto& o = offsets[first + std::min(m, lanes - 1)]; // a short batch repeats its last offset
        corner[m] = &values_[at(o[0] + radius_, o[1] + radius_, o[2] + radius_)];
      }
      const int b = 2 * h_ + 1;
      std::size_t n = 0;
      for (int z = 0; z < b; ++z)
        for (int y = 0; y < b; ++y, n += std::size_t(b)) {
          const std::size_t row = std::size_t(width_) * (std::size_t(y) + std::size_t(width_) * std::size_t(z));
          const double* s = &source.values[n];
          for (int x = 0; x < b; ++x) {
            const double a = s[x];
            for (std::size_t m = 0; m < Lanes; ++m) product[m] += a * corner[m][row + std::size_t(x)];
          }
        }
      for (std::size_t m = 0; m < lanes; ++m) {
        const auto& o = offsets[first + m];
        const std::size_t k = offsetIndex(o[0] + radius_, o[1] + radius_, o[2] + radius_);
        const double variance = squares_[k] - sums_[k] * sums_[k] / double(n);
        // Flat: no variance beyond the sums' rounding (a constant window's sliding sums keep a
        // residue of the voxels they slid past).
        const bool flat = variance <= 1e-12 || variance <= 1e-10 * squares_[k];
        scores[first + m] = !inside_[k] || source.norm <= 0 || flat ? -2.0 : product[m] / (source.norm * std::sqrt(variance));
      }
    }
  }

private:
  /// Box sums of 2h + 1 along x, then y, then z of a window-sized volume: one value per offset.
  std::vector<double> boxSums(const std::vector<double>& in) const
  {
    const std::size_t w = std::size_t(width_);
    const int b = 2 * h_ + 1, o = offsets_;
    const std::size_t ow = std::size_t(o);
    std::vector<double> sx(ow * w * w), sy(ow * ow * w), out(ow * ow * ow, 0.0);
    for (std::size_t line = 0; line < w * w; ++line) slidingSums(&in[line * w], 1, &sx[line * ow], 1, o, b); // x: lines (y, z)
    for (std::size_t z = 0; z < w; ++z) // y: lines (x, z) of the x sums
      for (std::size_t x = 0; x < ow; ++x) slidingSums(&sx[x + ow * w * z], ow, &sy[x + ow * ow * z], ow, o, b);
    for (std::size_t line = 0; line < ow * ow; ++line) slidingSums(&sy[line], ow * ow, &out[line], ow * ow, o, b); // z: lines (x, y)
    return out;
  }
  /// Each offset's window sum and sum of squares.
  void windowSums()
  {
    std::vector<double> squared(values_.size());
    for (std::size_t v = 0; v < values_.size(); ++v) squared[v] = values_[v] * values_[v];
    sums_ = boxSums(values_);
    squares_ = boxSums(squared);
  }
  /// `target` at continuous grid index c, trilinear, into `value`; false (value 0) beyond its
  /// outermost voxel centres.
  static bool trilinear(const Volume<float>& target, const double c[3], double& value)
  {
    int base[3];
    double f[3];
    for (int a = 0; a < 3; ++a) {
      if (!(c[a] >= 0.0 && c[a] <= double(target.size[std::size_t(a)] - 1))) {
        value = 0.0;
        return false;
      }
      base[a] = std::min(int(c[a]), std::max(0, target.size[std::size_t(a)] - 2));
      f[a] = c[a] - double(base[a]);
    }
    const std::size_t sy = std::size_t(target.size[0]), sz = sy * std::size_t(target.size[1]);
    const float* p = &target.values[target.at(base[0], base[1], base[2])];
    // A one-voxel axis has no neighbour: its fraction is 0 there, and its step is not taken.
    const std::size_t dx = target.size[0] > 1 ? 1 : 0, dy = target.size[1] > 1 ? sy : 0, dz = target.size[2] > 1 ? sz : 0;
    const double x00 = p[0] + (p[dx] - p[0]) * f[0], x10 = p[dy] + (p[dx + dy] - p[dy]) * f[0];
    const double x01 = p[dz] + (p[dx + dz] - p[dz]) * f[0], x11 = p[dy + dz] + (p[dx + dy + dz] - p[dy + dz]) * f[0];
    const double y0 = x00 + (x10 - x00) * f[1], y1 = x01 + (x11 - x01) * f[1];
    value = y0 + (y1 - y0) * f[2];
    return true;
  }
  std::size_t at(int x, int y, int z) const
  {
    return std::size_t(x) + std::size_t(width_) * (std::size_t(y) + std::size_t(width_) * std::size_t(z));
  }
  std::size_t offsetIndex(int x, int y, int z) const
  {
    return std::size_t(x) + std::size_t(offsets_) * (std::size_t(y) + std::size_t(offsets_) * std::size_t(z));
  }
  int radius_, h_, width_, offsets_;
  std::vector<double> values_, sums_, squares_;
  std::vector<unsigned char> inside_;
};

struct GridGeometry {
  itk::Matrix<double, 3, 3> indexToPhysical; ///< D S
  itk::Matrix<double, 3, 3> physicalToIndex; ///< S^-1 D^T
  std::array<double, 3> spacing{};
};

GridGeometry geometryOf(const ScalarImage& grid)
{
  GridGeometry g;
  itk::Matrix<double, 3, 3> scale;
  scale.Fill(0);
  for (int d = 0; d < 3; ++d) {
    scale(d, d) = grid.GetSpacing()[d];
    g.spacing[std::size_t(d)] = grid.GetSpacing()[d];
  }
  g.indexToPhysical = grid.GetDirection() * scale;
  g.physicalToIndex = g.indexToPhysical.GetInverse();
  return g;
}

/// The normalised gradient structure tensor of the remapped image over the block (physical axes).
std::array<double, 6> structureTensor(const Volume<float>& image, int ci, int cj, int ck, int h, const GridGeometry& geometry)
{
  double G[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
  for (int k = ck - h; k <= ck + h; ++k)
    for (int j = cj - h; j <= cj + h; ++j)
      for (int i = ci - h; i <= ci + h; ++i) {
        const double gi = (image.values[image.at(i + 1, j, k)] - image.values[image.at(i - 1, j, k)]) / (2 * geometry.spacing[0]);
        const double gj = (image.values[image.at(i, j + 1, k)] - image.values[image.at(i, j - 1, k)]) / (2 * geometry.spacing[1]);
        const double gk = (image.values[image.at(i, j, k + 1)] - image.values[image.at(i, j, k - 1)]) / (2 * geometry.spacing[2]);
        // Gradient in physical axes: D g (index axes, already per mm).
        double g[3];
        for (int a = 0; a < 3; ++a) {
          const auto& D = geometry.indexToPhysical;
          g[a] = (D(a, 0) / geometry.spacing[0]) * gi + (D(a, 1) / geometry.spacing[1]) * gj + (D(a, 2) / geometry.spacing[2]) * gk;
        }
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b) G[a][b] += g[a] * g[b];
      }
  double v[3] = {1, 0.7, 0.4}, largest = 0;
  for (int iteration = 0; iteration < 40; ++iteration) {
    double w[3];
    for (int a = 0; a < 3; ++a) w[a] = G[a][0] * v[0] + G[a][1] * v[1] + G[a][2] * v[2];
    largest = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    if (!(largest > 0)) return {};
    for (int a = 0; a < 3; ++a) v[a] = w[a] / largest;
  }
  return {G[0][0] / largest, G[0][1] / largest, G[0][2] / largest, G[1][1] / largest, G[1][2] / largest, G[2][2] / largest};
}

/// What became of one block (whose centre and predicted displacement `match` holds).
enum class Outcome { Matched, LowSimilarity, OutsideBrain, AtSearchEdge };

struct MatchingContext {
  const Volume<float>& remappedPreop;
  const Volume<float>& intraop;
  const Volume<LabelPixel>& intraopLabels;
  const GridGeometry& geometry;
  const BlockMatchingParameters& parameters;
  int h = 0, radius = 0, coarseStep = 1;
};

bool isBrain(const std::vector<int>& labels, LabelPixel label) { return std::find(labels.begin(), labels.end(), int(label)) != labels.end(); }

/// The best offset of a block's search and its correlation.
struct SearchPeak {
  std::array<int, 3> offset{0, 0, 0};
  double score = -3;
};

/// A coarse pass over the window (every `coarseStep` voxels), then a hill-climb at one voxel
/// around the peak until it stays; offsets are scored in lanes but taken in the loops' order, so a
/// tie goes to the first as it always did.
SearchPeak searchPeak(const SearchWindow& window, const SourceBlock& source, int radius, int coarseStep)
{
  SearchPeak peak;
  std::vector<std::array<int, 3>> offsets;
  std::vector<double> scores;
  auto takeBest = [&] {
    scores.resize(offsets.size());
    window.correlations(source, offsets.data(), offsets.size(), scores.data());
    for (std::size_t o = 0; o < offsets.size(); ++o) {
      if (scores[o] > peak.score) peak = {offsets[o], scores[o]};
    }
  };
  const int coarseReach = radius / coarseStep * coarseStep;
  for (int z = -coarseReach; z <= coarseReach; z += coarseStep)
    for (int y = -coarseReach; y <= coarseReach; y += coarseStep)
      for (int x = -coarseReach; x <= coarseReach; x += coarseStep) offsets.push_back({x, y, z});
  takeBest();
  for (int pass = 0; pass < 4; ++pass) {
    const std::array<int, 3> around = peak.offset;
    const int reach = pass == 0 ? coarseStep - 1 : 1;
    offsets.clear();
    for (int z = -reach; z <= reach; ++z)
      for (int y = -reach; y <= reach; ++y)
        for (int x = -reach; x <= reach; ++x) {
          const std::array<int, 3> o{around[0] + x, around[1] + y, around[2] + z};
          if (std::abs(o[0]) <= radius && std::abs(o[1]) <= radius && std::abs(o[2]) <= radius) offsets.push_back(o);
        }
    takeBest();
    if (peak.offset == around && pass > 0) break;
  }
  return peak;
}

/// The prediction's gradient at a block's centre, in the matching grid's voxels (d index / d index):
/// the window is sampled along I + this. Absent: the window is translated alone.
using PredictedGradient = std::optional<std::array<std::array<double, 3>, 3>>;

/// Whether the scan's classification calls at least the minimum brain share of the block about
/// `at` (grid voxels) brain (a voxel beyond the grid is not).
bool mostlyBrainAround(const MatchingContext& c, const std::array<int, 3>& at)
{
  std::size_t brain = 0, total = 0;
  for (int k = at[2] - c.h; k <= at[2] + c.h; ++k)
    for (int j = at[1] - c.h; j <= at[1] + c.h; ++j)
      for (int i = at[0] - c.h; i <= at[0] + c.h; ++i, ++total) {
        const bool inGrid = i >= 0 && j >= 0 && k >= 0 && i < c.intraopLabels.size[0] && j < c.intraopLabels.size[1] && k < c.intraopLabels.size[2];
        brain += inGrid && isBrain(c.parameters.brainLabels, c.intraopLabels.values[c.intraopLabels.at(i, j, k)]);
      }
  return !(double(brain) < c.parameters.minimumBrainShare * double(total));
}

Outcome matchOne(const MatchingContext& c, const std::array<int, 3>& centre, const PredictedGradient& gradient, BlockMatch& match)
{
  const SourceBlock source = sourceBlock(c.remappedPreop, centre[0], centre[1], centre[2], c.h);
  std::array<double, 3> predictedIndex{}; // the predicted displacement in grid voxels
  std::array<int, 3> start{};
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) predictedIndex[std::size_t(a)] += c.geometry.physicalToIndex(a, b) * match.predicted[std::size_t(b)];
    start[std::size_t(a)] = centre[std::size_t(a)] + int(std::lround(predictedIndex[std::size_t(a)]));
  }
  // The window's voxel o from the block's centre lies at start + stretch o in the grid (start in
  // whole voxels, as the translated window's: the deformed one's centre is the grid's own voxel).
  std::array<std::array<double, 3>, 3> stretch{};
  for (std::size_t a = 0; a < 3; ++a)
    for (std::size_t b = 0; b < 3; ++b) stretch[a][b] = (a == b ? 1.0 : 0.0) + (gradient ? (*gradient)[a][b] : 0.0);
  const SearchWindow window = gradient ? SearchWindow(c.intraop, {double(start[0]), double(start[1]), double(start[2])}, stretch, c.radius, c.h)
                                       : SearchWindow(c.intraop, start, c.radius, c.h);
  const SearchPeak peak = searchPeak(window, source, c.radius, c.coarseStep);
  const std::array<int, 3>& best = peak.offset;
  const double bestScore = peak.score;
  auto score = [&](const std::array<int, 3>& o) {
    double value = 0;
    window.correlations(source, &o, 1, &value);
    return value;
  };
  match.similarity = bestScore;
  if (bestScore < c.parameters.minimumSimilarity) return Outcome::LowSimilarity;
  if (std::abs(best[0]) >= c.radius || std::abs(best[1]) >= c.radius || std::abs(best[2]) >= c.radius) return Outcome::AtSearchEdge;
  // Sub-voxel: a parabola through the peak and its two neighbours, per axis.
  std::array<double, 3> sub{0, 0, 0};
  double fall = 0;
  for (int a = 0; a < 3; ++a) {
    std::array<int, 3> minus = best, plus = best;
    minus[std::size_t(a)] -= 1;
    plus[std::size_t(a)] += 1;
    const double sm = score(minus), sp = score(plus), curvature = sm + sp - 2 * bestScore;
    fall += (2 * bestScore - sm - sp) / 2;
    if (curvature < 0) sub[std::size_t(a)] = std::clamp(0.5 * (sm - sp) / curvature, -0.5, 0.5);
  }
  match.sharpness = fall / 3;
  // The matched place, in grid voxels from the block's centre: where the window's offset lies.
  std::array<double, 3> moved{};
  for (std::size_t a = 0; a < 3; ++a) {
    moved[a] = double(start[a] - centre[a]);
    for (std::size_t b = 0; b < 3; ++b) moved[a] += stretch[a][b] * (best[b] + sub[b]);
  }
  // The matched block must be brain in the scan (not the cavity, the gap or the skull).
  std::array<int, 3> at{};
  for (std::size_t a = 0; a < 3; ++a) at[a] = gradient ? centre[a] + int(std::lround(moved[a])) : start[a] + best[a];
  if (!mostlyBrainAround(c, at)) return Outcome::OutsideBrain;
  for (int a = 0; a < 3; ++a) {
    double d = 0;
    for (int b = 0; b < 3; ++b) d += c.geometry.indexToPhysical(a, b) * (gradient ? moved[std::size_t(b)] : at[std::size_t(b)] - centre[std::size_t(b)] + sub[std::size_t(b)]);
    match.displacement[std::size_t(a)] = d;
  }
  match.structure = structureTensor(c.remappedPreop, centre[0], centre[1], centre[2], c.h, c.geometry);
  return Outcome::Matched;
}

/// `volume` convolved along each grid axis with a sampled Gaussian of `sigmaMm`, cut at three
/// sigmas; at the grid's faces the kernel is cut off there and renormalised over what it covers.
/// Row by row (contiguous lines of the first axis, summed whole), so that it vectorises: 0.08-0.14 s
/// for one image of 200 x 230 x 200 voxels on this project's 2-core machine, where ITK's
/// DiscreteGaussianImageFilter took 0.23 s and its recursive Gaussian 0.28-0.31 s (the latter
/// inexact below a voxel's sigma), each besides the copies into and out of an itk::Image.
void smoothGaussian(Volume<float>& volume, const std::array<double, 3>& spacing, double sigmaMm)
{
  std::vector<float> scratch(volume.values.size());
  const std::array<int, 3> size = volume.size;
  const std::size_t rowLength = std::size_t(size[0]);
  for (int axis = 0; axis < 3; ++axis) {
    const double sigma = sigmaMm / spacing[std::size_t(axis)]; // in voxels
    const int reach = int(std::ceil(3 * sigma));
    const int length = size[std::size_t(axis)];
    if (reach < 1 || length < 2) continue;
    std::vector<float> kernel(std::size_t(2 * reach + 1));
    double total = 0;
    for (int t = -reach; t <= reach; ++t) total += std::exp(-0.5 * double(t * t) / (sigma * sigma));
    for (int t = -reach; t <= reach; ++t) kernel[std::size_t(t + reach)] = float(std::exp(-0.5 * double(t * t) / (sigma * sigma)) / total);
    auto weightOver = [&](int from, int to) { // the kernel's weight over offsets [from, to]
      float w = 0;
      for (int t = from; t <= to; ++t) w += kernel[std::size_t(t + reach)];
      return w;
    };
    const float* in = volume.values.data();
    float* out = scratch.data();
    parallelRanges(std::size_t(size[2]), [&](std::size_t kBegin, std::size_t kEnd, unsigned) {
      for (int k = int(kBegin); k < int(kEnd); ++k)
        for (int j = 0; j < size[1]; ++j) {
          float* o = out + volume.at(0, j, k);
          if (axis == 0) {
            const float* r = in + volume.at(0, j, k);
            for (int i = 0; i < length; ++i) {
              if (i >= reach && i + reach < length) continue; // the interior below
              const int from = std::max(-reach, -i), to = std::min(reach, length - 1 - i);
              float sum = 0;
              for (int t = from; t <= to; ++t) sum += kernel[std::size_t(t + reach)] * r[i + t];
              o[i] = sum / weightOver(from, to);
            }
            if (length > 2 * reach) {
              std::fill(o + reach, o + length - reach, 0.0f);
              for (int t = -reach; t <= reach; ++t) {
                const float w = kernel[std::size_t(t + reach)];
                for (int i = reach; i < length - reach; ++i) o[i] += w * r[i + t];
              }
            }
          } else {
            const int along = axis == 1 ? j : k;
            const int from = std::max(-reach, -along), to = std::min(reach, length - 1 - along);
            const float scale = 1.0f / weightOver(from, to);
            std::fill(o, o + rowLength, 0.0f);
            for (int t = from; t <= to; ++t) {
              const float w = kernel[std::size_t(t + reach)] * scale;
              const float* r = in + (axis == 1 ? volume.at(0, j + t, k) : volume.at(0, j, k + t));
              for (std::size_t i = 0; i < rowLength; ++i) o[i] += w * r[i];
            }
          }
        }
    });
    volume.values.swap(scratch);
  }
}

/// The matching grid and what lives on it: the preoperative image remapped into the scan's
/// contrast, its labels, the scan and its classification brought over by the rigid transform.
struct MatchingVolumes {
  ScalarImage::Pointer grid;
  Volume<float> remapped, intraop;
  Volume<LabelPixel> preopLabels, intraopLabels;
  std::vector<unsigned char> preopBrain;
};

MatchingVolumes prepareVolumes(const ScalarImage& preopImage, const LabelImage& preopLabels, const ScalarImage& intraopImage,
                               const LabelImage& intraopLabels, const SpatialTransform& rigidIntraopToPreop,
                               const BlockMatchingParameters& parameters, double& correlationRatio)
{
  MatchingVolumes v;
  v.grid = matchingGrid(preopImage, preopLabels, parameters);
  if (!v.grid) return v;
  const auto preopToIntraop = rigidIntraopToPreop.GetInverseTransform();
  if (!preopToIntraop) throw std::invalid_argument("block matching: the rigid transform cannot be inverted");
  // As ITK's ResampleImageFilter with its linear and nearest-neighbour interpolators, to rounding
  // (AffineResampling.h), in a seventh of the time.
  const ImageGeometry onGrid = ImageGeometry::of(v.grid.GetPointer());
  v.remapped = volumeOn(*v.grid, linearlyResampled(preopImage, onGrid, nullptr));
  v.preopLabels = volumeOn(*v.grid, nearestResampled(preopLabels, onGrid, nullptr));
  v.intraop = volumeOn(*v.grid, linearlyResampled(intraopImage, onGrid, preopToIntraop.GetPointer()));
  v.intraopLabels = volumeOn(*v.grid, nearestResampled(intraopLabels, onGrid, preopToIntraop.GetPointer()));
  const std::size_t voxels = v.remapped.values.size();
  std::vector<char> brainInBoth(voxels);
  v.preopBrain.resize(voxels);
  parallelRanges(voxels, [&](std::size_t begin, std::size_t end, unsigned) {
    for (std::size_t n = begin; n < end; ++n) {
      v.preopBrain[n] = isBrain(parameters.brainLabels, v.preopLabels.values[n]);
      brainInBoth[n] = v.preopBrain[n] && isBrain(parameters.brainLabels, v.intraopLabels.values[n]);
    }
  });
  const IntensityRemap remap = learnRemap(v.remapped, v.intraop, brainInBoth, correlationRatio);
  parallelRanges(voxels, [&](std::size_t begin, std::size_t end, unsigned) {
    for (std::size_t n = begin; n < end; ++n) v.remapped.values[n] = float(remap(v.remapped.values[n]));
  });
  if (parameters.smoothingMm > 0) {
    const std::array<double, 3> spacing{v.grid->GetSpacing()[0], v.grid->GetSpacing()[1], v.grid->GetSpacing()[2]};
    smoothGaussian(v.remapped, spacing, parameters.smoothingMm);
    smoothGaussian(v.intraop, spacing, parameters.smoothingMm);
  }
  return v;
}

/// Whether the centre and every offset from it are brain (false where an offset leaves the grid).
bool deepInBrain(const MatchingVolumes& v, int i, int j, int k, const std::vector<std::array<long, 3>>& offsets)
{
  const auto& size = v.remapped.size;
  for (const auto& o : offsets) {
    const int x = i + int(o[0]), y = j + int(o[1]), z = k + int(o[2]);
    if (x < 0 || y < 0 || z < 0 || x >= size[0] || y >= size[1] || z >= size[2]) return false;
    if (!v.preopBrain[v.remapped.at(x, y, z)]) return false;
  }
  return true;
}

/// `scored` (most structured first) reordered in rounds: each round takes every cube's most
/// structured candidate not yet taken (cubes `cellMm` wide on the matching grid), the round's in
/// the order of `scored`. A prefix of the result is spread over the brain as evenly as the
/// candidates allow and, within each cube, the most structured. `cells`: the cubes holding
/// candidates; `cellsWithBlock`: those with one among the first `keep`.
std::vector<std::pair<double, std::array<int, 3>>> spreadOverCells(const std::vector<std::pair<double, std::array<int, 3>>>& scored,
                                                                     const itk::Vector<double, 3>& spacing, double cellMm, std::size_t keep,
                                                                     std::size_t& cells, std::size_t& cellsWithBlock)
{
  std::map<std::array<int, 3>, unsigned> seenInCell; // a candidate's rank within its cube
  std::vector<std::pair<unsigned, std::size_t>> roundAndOrder(scored.size());
  for (std::size_t c = 0; c < scored.size(); ++c) {
    std::array<int, 3> cell{};
    for (unsigned d = 0; d < 3; ++d) cell[d] = int(std::floor(scored[c].second[d] * spacing[d] / cellMm));
    roundAndOrder[c] = {seenInCell[cell]++, c};
  }
  std::sort(roundAndOrder.begin(), roundAndOrder.end());
  cells = seenInCell.size();
  cellsWithBlock = std::size_t(std::count_if(roundAndOrder.begin(), roundAndOrder.begin() + std::ptrdiff_t(std::min(keep, roundAndOrder.size())),
                                             [](const auto& roundOfCandidate) { return roundOfCandidate.first == 0; }));
  std::vector<std::pair<double, std::array<int, 3>>> spread;
  spread.reserve(scored.size());
  for (const auto& [round, c] : roundAndOrder) spread.push_back(scored[c]);
  return spread;
}

/// Lattice centres (every `stride` voxels) deep in the brain whose block holds no excluded tissue:
/// the share of them and at most the limit, the most structured (variance of the remapped block)
/// first, in the whole brain or cube by cube (`selectionCellMm`, spreadOverCells). The counts of
/// `result`: how many qualified before the share and the limit, and the cubes.
std::vector<std::array<int, 3>> selectCandidates(const MatchingVolumes& v, int h, int stride, const BlockMatchingParameters& parameters,
                                                 BlockMatchingResult& result)
{
  // Deep enough: no boundary voxel nearer than the depth, as voxelsAtLeastDeep tests it (the
  // signed Maurer distance's test, DistanceMapsTest), at the lattice's centres alone.
  const std::vector<std::array<long, 3>> depthOffsets = depthTestOffsets(v.grid->GetSpacing(), parameters.minimumDepthMm);
  const Volume<float>& image = v.remapped;
  auto excludedAt = [&](std::size_t at) {
    const auto& excluded = parameters.excludedLabels;
    return std::find(excluded.begin(), excluded.end(), int(v.preopLabels.values[at])) != excluded.end();
  };
  std::vector<std::pair<double, std::array<int, 3>>> scored;
  for (int k = h + 1; k + h + 1 < image.size[2]; k += stride)
    for (int j = h + 1; j + h + 1 < image.size[1]; j += stride)
      for (int i = h + 1; i + h + 1 < image.size[0]; i += stride) {
        if (!v.preopBrain[image.at(i, j, k)] || !deepInBrain(v, i, j, k, depthOffsets)) continue;
        bool excluded = false;
        double sum = 0, squares = 0, n = 0;
        for (int z = k - h; z <= k + h && !excluded; ++z)
          for (int y = j - h; y <= j + h && !excluded; ++y)
            for (int x = i - h; x <= i + h && !excluded; ++x) {
              const std::size_t at = image.at(x, y, z);
              excluded = excludedAt(at);
              sum += image.values[at];
              squares += double(image.values[at]) * image.values[at];
              n += 1;
            }
        if (!excluded) scored.push_back({squares / n - (sum / n) * (sum / n), {i, j, k}});
      }
  result.candidates = scored.size();
  // Ties broken by place, so the order does not depend on the sort's implementation.
  auto moreStructured = [](const auto& a, const auto& b) { return a.first > b.first || (a.first == b.first && a.second < b.second); };
  std::sort(scored.begin(), scored.end(), moreStructured);
  const std::size_t keep = std::min(parameters.maximumBlocks, std::size_t(std::ceil(parameters.selectedShare * double(scored.size()))));
  if (parameters.selectionCellMm > 0) {
    scored = spreadOverCells(scored, v.grid->GetSpacing(), parameters.selectionCellMm, keep, result.selectionCells, result.selectionCellsWithBlock);
  }
  std::vector<std::array<int, 3>> candidates;
  for (std::size_t c = 0; c < std::min(keep, scored.size()); ++c) candidates.push_back(scored[c].second);
  return candidates;
}

/// The prediction's gradient (physical) in the grid's voxels (d index / d index), when the
/// deformed window is asked for and worth it: a gradient whose norm (physical, Frobenius) is at
/// least kDeformedWindowMinimumGradient and at most kDeformedWindowMaximumGradient, and that neither
/// folds the block nor squeezes it below a fifth of its volume (the determinant of I + gradient at
/// least 0.2). Beyond the largest, the window's voxels would lie several voxels apart: the search and
/// its sub-voxel fit would no longer be on the grid's scale.
PredictedGradient gradientInVoxels(const std::optional<std::array<std::array<double, 3>, 3>>& physical, const GridGeometry& geometry)
{
  if (!physical) return std::nullopt;
  double squares = 0;
  for (const auto& row : *physical)
    for (double g : row) squares += g * g;
  const double norm = std::sqrt(squares);
  if (!(norm >= kDeformedWindowMinimumGradient && norm <= kDeformedWindowMaximumGradient)) return std::nullopt;
  std::array<std::array<double, 3>, 3> g{}; // P G D S
  for (unsigned a = 0; a < 3; ++a)
    for (unsigned b = 0; b < 3; ++b) {
      double sum = 0;
      for (unsigned m = 0; m < 3; ++m)
        for (unsigned n = 0; n < 3; ++n) sum += geometry.physicalToIndex(a, m) * (*physical)[m][n] * geometry.indexToPhysical(n, b);
      g[a][b] = sum;
    }
  const double determinant = (1 + g[0][0]) * ((1 + g[1][1]) * (1 + g[2][2]) - g[1][2] * g[2][1]) -
                             g[0][1] * (g[1][0] * (1 + g[2][2]) - g[1][2] * g[2][0]) + g[0][2] * (g[1][0] * g[2][1] - (1 + g[1][1]) * g[2][0]);
  if (!(determinant >= 0.2)) return std::nullopt;
  return g;
}

/// One block matched in its translated window and, with a gradient, in its deformed one too. The
/// deformed window's match is taken when it is a match and the translated one is not (low
/// similarity, at the search's edge, outside the brain) or correlates less.
Outcome matchBestWindow(const MatchingContext& context, const std::array<int, 3>& centre, const PredictedGradient& gradient, BlockMatch& match,
                        bool& deformedTaken)
{
  deformedTaken = false;
  const BlockMatch asPredicted = match;
  const Outcome translated = matchOne(context, centre, std::nullopt, match);
  if (!gradient) return translated;
  BlockMatch deformed = asPredicted;
  const Outcome outcome = matchOne(context, centre, gradient, deformed);
  if (outcome == Outcome::Matched && (translated != Outcome::Matched || deformed.similarity > match.similarity)) {
    match = deformed;
    deformedTaken = true;
    return outcome;
  }
  return translated;
}

/// Every candidate matched, the blocks shared between two threads; the outcomes counted.
void matchCandidates(const MatchingContext& context, const ScalarImage& grid, const std::vector<std::array<int, 3>>& candidates,
                     const DisplacementPrediction& prediction, BlockMatchingResult& result)
{
  std::vector<BlockMatch> matches(candidates.size());
  std::vector<PredictedGradient> gradients(candidates.size());
  for (std::size_t b = 0; b < candidates.size(); ++b) { // the prediction need not be thread-safe
    grid.TransformIndexToPhysicalPoint({{candidates[b][0], candidates[b][1], candidates[b][2]}}, matches[b].centre);
    const std::optional<PredictedDisplacement> predicted = prediction ? prediction(matches[b].centre) : std::nullopt;
    if (!predicted) continue;
    matches[b].predicted = predicted->displacement;
    if (context.parameters.deformedWindows) gradients[b] = gradientInVoxels(predicted->gradient, context.geometry);
  }
  std::vector<Outcome> outcomes(candidates.size(), Outcome::LowSimilarity);
  std::vector<char> deformedTaken(candidates.size(), 0);
  const unsigned threads = std::max(1u, std::min(2u, std::thread::hardware_concurrency()));
  std::vector<std::thread> workers;
  for (unsigned t = 0; t < threads; ++t) {
    workers.emplace_back([&, t] {
      for (std::size_t b = t; b < candidates.size(); b += threads) {
        bool taken = false;
        outcomes[b] = matchBestWindow(context, candidates[b], gradients[b], matches[b], taken);
        deformedTaken[b] = taken;
      }
    });
  }
  for (std::thread& w : workers) w.join();
  for (std::size_t b = 0; b < candidates.size(); ++b) {
    result.deformedWindows += gradients[b].has_value();
    result.deformedWindowsTaken += deformedTaken[b] && outcomes[b] == Outcome::Matched;
    switch (outcomes[b]) {
    case Outcome::Matched: result.matches.push_back(matches[b]); break;
    case Outcome::LowSimilarity: ++result.lowSimilarity; break;
    case Outcome::OutsideBrain: ++result.outsideBrain; break;
    case Outcome::AtSearchEdge: ++result.atSearchEdge; break;
    }
  }
}

/// The matching grid's spacing per axis and the block's half-size in its voxels, as matchBlocks
/// sets them for `preopImage`.
std::pair<std::array<double, 3>, int> blockLattice(const ScalarImage& preopImage, const BlockMatchingParameters& parameters)
{
  std::array<double, 3> spacing{};
  for (unsigned d = 0; d < 3; ++d) spacing[d] = std::max(preopImage.GetSpacing()[d], parameters.gridSpacingMm);
  const double largest = std::max({spacing[0], spacing[1], spacing[2]});
  return {spacing, std::max(1, int(std::lround(parameters.blockHalfSizeMm / largest)))};
}

} // namespace

BlockMatchingResult matchesStillInBrain(const BlockMatchingResult& earlier, const ScalarImage& preopImage, const LabelImage& intraopLabels,
                                        const SpatialTransform& rigidIntraopToPreop, const BlockMatchingParameters& parameters)
{
  requireSensible(parameters);
  const auto clock = Clock::now();
  const auto preopToIntraop = rigidIntraopToPreop.GetInverseTransform();
  if (!preopToIntraop) throw std::invalid_argument("block matching: the rigid transform cannot be inverted");
  const auto [spacing, h] = blockLattice(preopImage, parameters);
  const auto& direction = preopImage.GetDirection();
  const auto size = intraopLabels.GetLargestPossibleRegion().GetSize();
  const LabelPixel* labels = intraopLabels.GetBufferPointer();
  // The scan's continuous index of a preoperative point.
  auto indexOf = [&](const PhysicalPoint& x) {
    const auto c = intraopLabels.TransformPhysicalPointToContinuousIndex<double>(preopToIntraop->TransformPoint(x));
    return std::array<double, 3>{c[0], c[1], c[2]};
  };
  BlockMatchingResult result = earlier;
  result.matches.clear();
  for (const BlockMatch& match : earlier.matches) {
    // The matched block's centre and its axes' steps, in the scan's indices (the rigid map is affine).
    PhysicalPoint at;
    for (unsigned a = 0; a < 3; ++a) at[a] = match.centre[a] + match.displacement[a];
    const std::array<double, 3> base = indexOf(at);
    std::array<std::array<double, 3>, 3> step{};
    for (unsigned d = 0; d < 3; ++d) {
      PhysicalPoint next = at;
      for (unsigned a = 0; a < 3; ++a) next[a] += direction(a, d) * spacing[d];
      const std::array<double, 3> n = indexOf(next);
      for (unsigned a = 0; a < 3; ++a) step[d][a] = n[a] - base[a];
    }
    std::size_t brain = 0, total = 0;
    for (int k = -h; k <= h; ++k)
      for (int j = -h; j <= h; ++j)
        for (int i = -h; i <= h; ++i, ++total) {
          std::array<long, 3> index{};
          bool inside = true;
          for (unsigned a = 0; a < 3; ++a) {
            index[a] = std::lround(base[a] + i * step[0][a] + j * step[1][a] + k * step[2][a]);
            inside = inside && index[a] >= 0 && index[a] < long(size[a]);
          }
          if (inside) brain += isBrain(parameters.brainLabels, labels[std::size_t(index[0]) + size[0] * (std::size_t(index[1]) + size[1] * std::size_t(index[2]))]);
        }
    if (double(brain) < parameters.minimumBrainShare * double(total)) {
      ++result.outsideBrain;
    } else {
      result.matches.push_back(match);
    }
  }
  result.remapSeconds = 0;
  result.matchingSeconds = 0;
  result.selectionSeconds = secondsSince(clock);
  return result;
}

BlockMatchingResult matchBlocks(const ScalarImage& preopImage, const LabelImage& preopLabels, const ScalarImage& intraopImage,
                                const LabelImage& intraopLabels, const SpatialTransform& rigidIntraopToPreop,
                                const DisplacementPrediction& prediction, const BlockMatchingParameters& parameters)
{
  requireSensible(parameters);
  BlockMatchingResult result;
  auto clock = Clock::now();
  const MatchingVolumes volumes =
    prepareVolumes(preopImage, preopLabels, intraopImage, intraopLabels, rigidIntraopToPreop, parameters, result.remapCorrelationRatio);
  if (!volumes.grid) return result;
  result.remapSeconds = secondsSince(clock);

  clock = Clock::now();
  const GridGeometry geometry = geometryOf(*volumes.grid);
  const double spacing = std::max({geometry.spacing[0], geometry.spacing[1], geometry.spacing[2]});
  const int h = blockLattice(preopImage, parameters).second;
  const int stride = std::max(1, int(std::lround(parameters.blockSpacingMm / spacing)));
  const std::vector<std::array<int, 3>> candidates = selectCandidates(volumes, h, stride, parameters, result);
  result.selected = candidates.size();
  result.selectionSeconds = secondsSince(clock);

  clock = Clock::now();
  MatchingContext context{volumes.remapped, volumes.intraop, volumes.intraopLabels, geometry, parameters};
  context.h = h;
  context.radius = std::max(1, int(std::ceil(parameters.searchRadiusMm / spacing)));
  context.coarseStep = std::max(1, int(std::lround(parameters.coarseStepMm / spacing)));
  matchCandidates(context, *volumes.grid, candidates, prediction, result);
  result.matchingSeconds = secondsSince(clock);
  return result;
}

} // namespace brainshift
