#include "AffineResampling.h"

#include "ParallelRanges.h"

#include <array>
#include <cmath>
#include <stdexcept>

namespace brainshift {

namespace {

/// The image's continuous index of the grid's voxel (i, j, k): c = A (i, j, k) + t.
struct IndexMap {
  std::array<std::array<double, 3>, 3> a{}; ///< a[column][row]: the step of c per index of the grid's axis
  std::array<double, 3> t{};
};

template <class Image>
IndexMap indexMapOf(const Image& image, const ImageGeometry& grid, const SpatialTransform* gridToImage)
{
  if (gridToImage && !gridToImage->IsLinear()) throw std::invalid_argument("affine resampling: the transform is not linear");
  auto toImageIndex = [&](const std::array<double, 3>& index) {
    PhysicalPoint p;
    for (unsigned r = 0; r < 3; ++r) {
      p[r] = grid.origin[r];
      for (unsigned c = 0; c < 3; ++c) p[r] += grid.direction(r, c) * grid.spacing[c] * index[c];
    }
    if (gridToImage) p = gridToImage->TransformPoint(p);
    const auto c = image.template TransformPhysicalPointToContinuousIndex<double>(p);
    return std::array<double, 3>{c[0], c[1], c[2]};
  };
  IndexMap map;
  map.t = toImageIndex({0, 0, 0});
  for (std::size_t axis = 0; axis < 3; ++axis) {
    std::array<double, 3> unit{0, 0, 0};
    unit[axis] = 1;
    const std::array<double, 3> c = toImageIndex(unit);
    for (std::size_t r = 0; r < 3; ++r) map.a[axis][r] = c[r] - map.t[r];
  }
  return map;
}

/// Runs visit(out, c) for each voxel of the grid with its continuous index c in the image, on the
/// machine's cores (slices in contiguous ranges). With `displacement` (one vector a voxel of the
/// grid, in mm), the voxel's point is moved by its vector first: c gains `toIndex` times it.
template <class Visit>
void forEachVoxel(const ImageGeometry& grid, const IndexMap& map, Visit&& visit, const DisplacementVector* displacement = nullptr,
                  const std::array<std::array<double, 3>, 3>& toIndex = {})
{
  const std::size_t nx = grid.size[0], ny = grid.size[1], nz = grid.size[2];
  parallelRanges(nz, [&](std::size_t begin, std::size_t end, unsigned) {
    for (std::size_t k = begin; k < end; ++k)
      for (std::size_t j = 0; j < ny; ++j) {
        std::array<double, 3> row;
        for (std::size_t r = 0; r < 3; ++r) row[r] = map.t[r] + map.a[1][r] * double(j) + map.a[2][r] * double(k);
        std::size_t out = nx * (j + ny * k);
        for (std::size_t i = 0; i < nx; ++i, ++out) {
          double c[3] = {row[0] + map.a[0][0] * double(i), row[1] + map.a[0][1] * double(i), row[2] + map.a[0][2] * double(i)};
          if (displacement) {
            const DisplacementVector& d = displacement[out];
            for (std::size_t r = 0; r < 3; ++r) c[r] += toIndex[r][0] * double(d[0]) + toIndex[r][1] * double(d[1]) + toIndex[r][2] * double(d[2]);
          }
          visit(out, c);
        }
      }
  });
}

/// floor(x) for |x| < 2^62, without the library call (baseline x86-64 has no rounding instruction).
inline long floorOf(double x)
{
  const long truncated = long(x);
  return truncated - long(x < double(truncated));
}

/// ITK's test: within half a voxel of the outermost voxel centres (a NaN is outside).
inline bool insideBuffer(const double c[3], const long size[3])
{
  for (int a = 0; a < 3; ++a) {
    if (!(c[a] >= -0.5 && c[a] < double(size[a]) - 0.5)) return false;
  }
  return true;
}


/// `v` (of `size`) at continuous index c by ITK's linear interpolator, 0 outside its buffer.
/// As ITK's: the base voxel floor(c), not before the first; the distance from it; no step to a
/// neighbour at or below zero distance, nor past the last voxel (the formula below then takes the
/// same value twice: exactly the lower-dimensional interpolation).
inline float linearAt(const float* v, const long size[3], const double c[3])
{
  if (!insideBuffer(c, size)) return 0.0f;
  long base[3];
  double d[3];
  std::size_t step[3];
  const std::size_t strides[3] = {1, std::size_t(size[0]), std::size_t(size[0]) * std::size_t(size[1])};
  for (int a = 0; a < 3; ++a) {
    base[a] = std::max(0L, floorOf(c[a]));
    d[a] = c[a] - double(base[a]);
    step[a] = d[a] > 0 && base[a] + 1 < size[a] ? strides[a] : 0;
  }
  const float* p = v + std::size_t(base[0]) * strides[0] + std::size_t(base[1]) * strides[1] + std::size_t(base[2]) * strides[2];
  const double v000 = p[0], v100 = p[step[0]], v010 = p[step[1]], v110 = p[step[0] + step[1]];
  const double v001 = p[step[2]], v101 = p[step[0] + step[2]], v011 = p[step[1] + step[2]], v111 = p[step[0] + step[1] + step[2]];
  const double x00 = v000 + (v100 - v000) * d[0], x10 = v010 + (v110 - v010) * d[0];
  const double x01 = v001 + (v101 - v001) * d[0], x11 = v011 + (v111 - v011) * d[0];
  const double xy0 = x00 + (x10 - x00) * d[1], xy1 = x01 + (x11 - x01) * d[1];
  return float(xy0 + (xy1 - xy0) * d[2]);
}

/// `v` (of `size`) at continuous index c by ITK's nearest-neighbour interpolator (a half rounds
/// up), 0 outside its buffer.
inline LabelPixel nearestAt(const LabelPixel* v, const long size[3], const double c[3])
{
  if (!insideBuffer(c, size)) return LabelPixel(0);
  std::size_t at = 0, stride = 1;
  for (int a = 0; a < 3; ++a) {
    const long nearest = std::min(size[a] - 1, std::max(0L, floorOf(c[a] + 0.5)));
    at += std::size_t(nearest) * stride;
    stride *= std::size_t(size[a]);
  }
  return v[at];
}

template <class Image>
std::array<long, 3> sizeOf(const Image& image)
{
  const auto size = image.GetLargestPossibleRegion().GetSize();
  return {long(size[0]), long(size[1]), long(size[2])};
}

/// The image's physical-to-index matrix, rows first: the step of its continuous index per mm.
template <class Image>
std::array<std::array<double, 3>, 3> physicalToIndexOf(const Image& image)
{
  const auto inverseDirection = image.GetInverseDirection(); // the index's step is (direction diag(spacing))^-1
  std::array<std::array<double, 3>, 3> rows{};
  for (unsigned r = 0; r < 3; ++r)
    for (unsigned c = 0; c < 3; ++c) rows[r][c] = inverseDirection(r, c) / image.GetSpacing()[r];
  return rows;
}

/// Whether a region starts at index 0 on every axis.
template <class Region>
bool startsAtZero(const Region& region)
{
  for (unsigned a = 0; a < Region::ImageDimension; ++a) {
    if (region.GetIndex()[a] != 0) return false;
  }
  return true;
}

/// The field's vectors; refuses a field without its whole buffer.
const DisplacementVector* displacementsOf(const DisplacementFieldImage& field)
{
  const auto& region = field.GetLargestPossibleRegion();
  if (!field.GetBufferPointer() || field.GetBufferedRegion() != region || !startsAtZero(region)) {
    throw std::invalid_argument("warping: the displacement field holds no whole buffer from index 0");
  }
  return field.GetBufferPointer();
}

/// `image` by `at` (linearAt or nearestAt) at each voxel of `grid`: its point through `gridToImage`,
/// or moved by `field`'s vector (the field on `grid`). The image must hold its whole buffer from
/// index 0 (std::invalid_argument otherwise), as the field must.
template <class Image, class At>
std::vector<typename Image::PixelType> sampled(const Image& image, const ImageGeometry& grid, const SpatialTransform* gridToImage,
                                               const DisplacementFieldImage* field, At at)
{
  const auto& region = image.GetLargestPossibleRegion();
  if (!image.GetBufferPointer() || image.GetBufferedRegion() != region || !startsAtZero(region)) {
    throw std::invalid_argument("resampling: the image holds no whole buffer from index 0");
  }
  const DisplacementVector* displacement = field ? displacementsOf(*field) : nullptr;
  const IndexMap map = indexMapOf(image, grid, gridToImage);
  const std::array<long, 3> size = sizeOf(image);
  const typename Image::PixelType* v = image.GetBufferPointer();
  std::vector<typename Image::PixelType> result(grid.numberOfVoxels());
  forEachVoxel(
    grid, map, [&](std::size_t out, const double c[3]) { result[out] = at(v, size.data(), c); }, displacement, physicalToIndexOf(image));
  return result;
}

} // namespace

std::vector<float> linearlyResampled(const ScalarImage& image, const ImageGeometry& grid, const SpatialTransform* gridToImage)
{
  return sampled(image, grid, gridToImage, nullptr, linearAt);
}

std::vector<LabelPixel> nearestResampled(const LabelImage& image, const ImageGeometry& grid, const SpatialTransform* gridToImage)
{
  return sampled(image, grid, gridToImage, nullptr, nearestAt);
}

std::vector<float> linearlyWarped(const ScalarImage& image, const DisplacementFieldImage& field)
{
  return sampled(image, ImageGeometry::of(&field), nullptr, &field, linearAt);
}

std::vector<LabelPixel> nearestWarped(const LabelImage& image, const DisplacementFieldImage& field)
{
  return sampled(image, ImageGeometry::of(&field), nullptr, &field, nearestAt);
}

} // namespace brainshift
