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
/// machine's cores (slices in contiguous ranges).
template <class Visit>
void forEachVoxel(const ImageGeometry& grid, const IndexMap& map, Visit&& visit)
{
  const std::size_t nx = grid.size[0], ny = grid.size[1], nz = grid.size[2];
  parallelRanges(nz, [&](std::size_t begin, std::size_t end, unsigned) {
    for (std::size_t k = begin; k < end; ++k)
      for (std::size_t j = 0; j < ny; ++j) {
        std::array<double, 3> row;
        for (std::size_t r = 0; r < 3; ++r) row[r] = map.t[r] + map.a[1][r] * double(j) + map.a[2][r] * double(k);
        std::size_t out = nx * (j + ny * k);
        for (std::size_t i = 0; i < nx; ++i, ++out) {
          const double c[3] = {row[0] + map.a[0][0] * double(i), row[1] + map.a[0][1] * double(i), row[2] + map.a[0][2] * double(i)};
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

} // namespace

std::vector<float> linearlyResampled(const ScalarImage& image, const ImageGeometry& grid, const SpatialTransform* gridToImage)
{
  const IndexMap map = indexMapOf(image, grid, gridToImage);
  const auto imageSize = image.GetLargestPossibleRegion().GetSize();
  const long size[3] = {long(imageSize[0]), long(imageSize[1]), long(imageSize[2])};
  const float* v = image.GetBufferPointer();
  const std::size_t sx = 1, sy = std::size_t(size[0]), sz = std::size_t(size[0]) * std::size_t(size[1]);
  std::vector<float> result(grid.numberOfVoxels(), 0.0f);
  forEachVoxel(grid, map, [&](std::size_t out, const double c[3]) {
    if (!insideBuffer(c, size)) return;
    // As ITK's linear interpolator: the base voxel floor(c), not before the first; the distance
    // from it; no step to a neighbour at or below zero distance, nor past the last voxel (the
    // formula below then takes the same value twice: exactly the lower-dimensional interpolation).
    long base[3];
    double d[3];
    std::size_t step[3];
    const std::size_t strides[3] = {sx, sy, sz};
    for (int a = 0; a < 3; ++a) {
      base[a] = std::max(0L, floorOf(c[a]));
      d[a] = c[a] - double(base[a]);
      step[a] = d[a] > 0 && base[a] + 1 < size[a] ? strides[a] : 0;
    }
    const float* p = v + std::size_t(base[0]) * sx + std::size_t(base[1]) * sy + std::size_t(base[2]) * sz;
    const double v000 = p[0], v100 = p[step[0]], v010 = p[step[1]], v110 = p[step[0] + step[1]];
    const double v001 = p[step[2]], v101 = p[step[0] + step[2]], v011 = p[step[1] + step[2]], v111 = p[step[0] + step[1] + step[2]];
    const double x00 = v000 + (v100 - v000) * d[0], x10 = v010 + (v110 - v010) * d[0];
    const double x01 = v001 + (v101 - v001) * d[0], x11 = v011 + (v111 - v011) * d[0];
    const double xy0 = x00 + (x10 - x00) * d[1], xy1 = x01 + (x11 - x01) * d[1];
    result[out] = float(xy0 + (xy1 - xy0) * d[2]);
  });
  return result;
}

std::vector<LabelPixel> nearestResampled(const LabelImage& image, const ImageGeometry& grid, const SpatialTransform* gridToImage)
{
  const IndexMap map = indexMapOf(image, grid, gridToImage);
  const auto imageSize = image.GetLargestPossibleRegion().GetSize();
  const long size[3] = {long(imageSize[0]), long(imageSize[1]), long(imageSize[2])};
  const LabelPixel* v = image.GetBufferPointer();
  std::vector<LabelPixel> result(grid.numberOfVoxels(), LabelPixel(0));
  forEachVoxel(grid, map, [&](std::size_t out, const double c[3]) {
    if (!insideBuffer(c, size)) return;
    std::size_t at = 0, stride = 1;
    for (int a = 0; a < 3; ++a) {
      const long nearest = std::min(size[a] - 1, std::max(0L, floorOf(c[a] + 0.5)));
      at += std::size_t(nearest) * stride;
      stride *= std::size_t(size[a]);
    }
    result[out] = v[at];
  });
  return result;
}

} // namespace brainshift
