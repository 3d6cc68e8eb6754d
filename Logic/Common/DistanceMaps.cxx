#include "DistanceMaps.h"

#include <itkSignedMaurerDistanceMapImageFilter.h>

#include <array>
#include <cmath>
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
// voxel (which is a boundary voxel): the boundary voxels' closed balls, and the mask.
MaskImage::Pointer voxelsWithin(const MaskImage* mask, double reachMm)
{
  MaskImage::Pointer within = emptyLike(mask);
  const std::vector<Offset> offsets = ballOffsets(mask->GetSpacing(), reachMm, true, false);
  const MaskLookup in = lookupOf(mask);
  unsigned char* out = within->GetBufferPointer();
  auto boundary = [&in](long x, long y, long z) {
    for (long c = -1; c <= 1; ++c)
      for (long b = -1; b <= 1; ++b)
        for (long a = -1; a <= 1; ++a)
          if (!in(x + a, y + b, z + c)) return true;
    return false;
  };
  std::size_t n = 0;
  for (long z = 0; z < in.size[2]; ++z)
    for (long y = 0; y < in.size[1]; ++y)
      for (long x = 0; x < in.size[0]; ++x, ++n) {
        if (!in.m[n]) continue;
        out[n] = 1;
        if (!boundary(x, y, z)) continue;
        for (const Offset& o : offsets) {
          const long px = x + o[0], py = y + o[1], pz = z + o[2];
          if (px < 0 || py < 0 || pz < 0 || px >= in.size[0] || py >= in.size[1] || pz >= in.size[2]) continue;
          out[std::size_t(px + in.size[0] * (py + in.size[1] * pz))] = 1;
        }
      }
  return within;
}

} // namespace brainshift
