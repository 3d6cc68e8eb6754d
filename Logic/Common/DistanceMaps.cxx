#include "DistanceMaps.h"

#include "ParallelRanges.h"

#include <itkSignedMaurerDistanceMapImageFilter.h>

#include <array>
#include <cmath>
#include <limits>
#include <vector>

namespace brainshift {
namespace {

using Offset = std::array<long, 3>;

/// The voxel offsets within `radiusMm` (strictly nearer, or also at that distance) on `spacing`,
/// each also moved by one voxel in every direction when `grownByOne`.
std::vector<Offset> ballOffsets(const MaskImage::SpacingType& spacing, double radiusMm, bool closed, bool grownByOne)
{
  const long grow = grownByOne ? 1 : 0;
  Offset reach{};
  for (unsigned a = 0; a < 3; ++a) reach[a] = long(std::ceil(radiusMm / spacing[a])) + grow;
  std::vector<Offset> offsets;
  for (long z = -reach[2]; z <= reach[2]; ++z)
    for (long y = -reach[1]; y <= reach[1]; ++y)
      for (long x = -reach[0]; x <= reach[0]; ++x) {
        bool inside = false;
        for (long c = -grow; c <= grow && !inside; ++c)
          for (long b = -grow; b <= grow && !inside; ++b)
            for (long a = -grow; a <= grow && !inside; ++a) {
              const double dx = double(x - a) * spacing[0], dy = double(y - b) * spacing[1], dz = double(z - c) * spacing[2];
              const double squared = dx * dx + dy * dy + dz * dz, limit = radiusMm * radiusMm;
              inside = closed ? squared <= limit : squared < limit;
            }
        if (inside) offsets.push_back({x, y, z});
      }
  return offsets;
}

MaskImage::Pointer emptyLike(const MaskImage* mask)
{
  auto out = MaskImage::New();
  out->CopyInformation(mask);
  out->SetRegions(mask->GetLargestPossibleRegion());
  out->Allocate();
  out->FillBuffer(0);
  return out;
}

/// The mask's voxel at (x, y, z) (false outside the grid).
struct MaskLookup {
  const unsigned char* m;
  std::array<long, 3> size;
  bool operator()(long x, long y, long z) const
  {
    if (x < 0 || y < 0 || z < 0 || x >= size[0] || y >= size[1] || z >= size[2]) return false;
    return m[std::size_t(x + size[0] * (y + size[1] * z))] != 0;
  }
};

MaskLookup lookupOf(const MaskImage* mask)
{
  const auto size = mask->GetLargestPossibleRegion().GetSize();
  return {mask->GetBufferPointer(), {long(size[0]), long(size[1]), long(size[2])}};
}
} // namespace

ScalarImage::Pointer signedDistanceMm(const MaskImage* mask)
{
  auto distance = itk::SignedMaurerDistanceMapImageFilter<MaskImage, ScalarImage>::New();
  distance->SetInput(mask);
  distance->SetUseImageSpacing(true);
  distance->SetSquaredDistance(false);
  distance->SetInsideIsPositive(false);
  distance->SetBackgroundValue(0);
  distance->Update();
  ScalarImage::Pointer out = distance->GetOutput();
  out->DisconnectPipeline();
  return out;
}

ScalarImage::Pointer boundaryDistanceMm(const MaskImage* mask)
{
  auto complement = MaskImage::New();
  complement->SetRegions(mask->GetLargestPossibleRegion());
  complement->CopyInformation(mask);
  complement->Allocate();
  const unsigned char* m = mask->GetBufferPointer();
  unsigned char* c = complement->GetBufferPointer();
  const std::size_t n = mask->GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) c[i] = m[i] ? 0 : 1;
  ScalarImage::Pointer inside = signedDistanceMm(mask);
  const ScalarImage::Pointer outside = signedDistanceMm(complement);
  float* a = inside->GetBufferPointer();
  const float* b = outside->GetBufferPointer();
  for (std::size_t i = 0; i < n; ++i) a[i] = 0.5f * (a[i] - b[i]);
  return inside;
}

} // namespace brainshift

namespace brainshift {

// A boundary voxel nearer than depthMm exists exactly when the open ball about the voxel, grown by
// one voxel, holds a voxel of the complement: a complement voxel in the ball makes the path towards
// the centre cross a boundary voxel, itself in the ball.
std::vector<std::array<long, 3>> depthTestOffsets(const MaskImage::SpacingType& spacing, double depthMm)
{
  return ballOffsets(spacing, depthMm, false, true);
}

MaskImage::Pointer voxelsAtLeastDeep(const MaskImage* mask, double depthMm)
{
  MaskImage::Pointer deep = emptyLike(mask);
  const std::vector<Offset> offsets = depthTestOffsets(mask->GetSpacing(), depthMm);
  const MaskLookup in = lookupOf(mask);
  unsigned char* out = deep->GetBufferPointer();
  std::size_t n = 0;
  for (long z = 0; z < in.size[2]; ++z)
    for (long y = 0; y < in.size[1]; ++y)
      for (long x = 0; x < in.size[0]; ++x, ++n) {
        if (!in.m[n]) continue;
        bool all = true;
        for (const Offset& o : offsets) {
          if (!in(x + o[0], y + o[1], z + o[2])) {
            all = false;
            break;
          }
        }
        out[n] = all;
      }
  return deep;
}

// Outside the mask the distance to its nearest boundary voxel is the distance to its nearest
// voxel (which is a boundary voxel), so the selection is the voxels whose squared distance to the
// nearest mask voxel is at most the reach's square (the mask itself at 0). The squared distance to
// the nearest mask voxel by the separable exact transform (along the rows, then the columns, then
// the slices: the nearest along each axis of the nearest along the ones before), each pass over
// the offsets within the reach alone. The sums run in the order the ball's
// test adds them (dx^2 + dy^2, then + dz^2) and rounding is monotonic, so the minimum over the
// passes is the smallest sum the ball's test would form: voxel for voxel the same selection as
// splatting the closed ball from every mask voxel, at a few operations a voxel.
MaskImage::Pointer voxelsWithin(const MaskImage* mask, double reachMm)
{
  MaskImage::Pointer within = emptyLike(mask);
  const MaskLookup in = lookupOf(mask);
  const MaskImage::SpacingType spacing = mask->GetSpacing();
  const long nx = in.size[0], ny = in.size[1], nz = in.size[2];
  const std::size_t rowLength = std::size_t(nx), planeSize = std::size_t(nx * ny), n = planeSize * std::size_t(nz);
  const double limit = reachMm * reachMm, infinity = std::numeric_limits<double>::infinity();
  std::vector<double> alongRows(n, infinity), alongPlanes(n, infinity);
  // Along x: the nearer of the row's nearest mask voxels on either side.
  parallelRanges(std::size_t(ny * nz), [&](std::size_t begin, std::size_t end, unsigned) {
    for (std::size_t row = begin; row < end; ++row) {
      const unsigned char* m = in.m + row * rowLength;
      double* h = &alongRows[row * rowLength];
      long nearest = -1;
      for (long x = 0; x < nx; ++x) {
        if (m[x]) nearest = x;
        if (nearest < 0) continue;
        const double dx = double(x - nearest) * spacing[0];
        h[x] = dx * dx;
      }
      nearest = -1;
      for (long x = nx - 1; x >= 0; --x) {
        if (m[x]) nearest = x;
        if (nearest < 0) continue;
        const double dx = double(nearest - x) * spacing[0];
        h[x] = std::min(h[x], dx * dx);
      }
    }
  });
  // Along y, then z: offsets up to the reach (one more against rounding; the test drops what lies beyond).
  const long reachY = long(std::ceil(reachMm / spacing[1])) + 1, reachZ = long(std::ceil(reachMm / spacing[2])) + 1;
  parallelRanges(std::size_t(nz), [&](std::size_t zBegin, std::size_t zEnd, unsigned) {
    for (long z = long(zBegin); z < long(zEnd); ++z) {
      for (long y = 0; y < ny; ++y) {
        double* out = &alongPlanes[std::size_t(z) * planeSize + std::size_t(y) * rowLength];
        for (long dy = -reachY; dy <= reachY; ++dy) {
          if (y + dy < 0 || y + dy >= ny) continue;
          const double step = double(dy) * spacing[1], add = step * step;
          const double* from = &alongRows[std::size_t(z) * planeSize + std::size_t(y + dy) * rowLength];
          for (std::size_t x = 0; x < rowLength; ++x) out[x] = std::min(out[x], from[x] + add);
        }
      }
    }
  });
  unsigned char* selected = within->GetBufferPointer();
  parallelRanges(std::size_t(nz), [&](std::size_t zBegin, std::size_t zEnd, unsigned) {
    for (long z = long(zBegin); z < long(zEnd); ++z) {
      double* best = &alongRows[std::size_t(z) * planeSize]; // this slice's rows are no longer read
      std::fill(best, best + planeSize, infinity);
      for (long dz = -reachZ; dz <= reachZ; ++dz) {
        if (z + dz < 0 || z + dz >= nz) continue;
        const double step = double(dz) * spacing[2], add = step * step;
        const double* from = &alongPlanes[std::size_t(z + dz) * planeSize];
        for (std::size_t i = 0; i < planeSize; ++i) best[i] = std::min(best[i], from[i] + add);
      }
      unsigned char* out = selected + std::size_t(z) * planeSize;
      for (std::size_t i = 0; i < planeSize; ++i) out[i] = best[i] <= limit ? 1 : 0;
    }
  });
  return within;
}

} // namespace brainshift
