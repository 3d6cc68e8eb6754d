// Boundary nodes moved onto the label boundaries: a sphere's surface is smooth (its nodes near the
// true radius, where the lattice alone leaves a staircase), the volumes match the voxels, and a
// noisy label map still gives a valid mesh with closed surfaces.
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "LabelMapMesher.h"

#include <itkImageRegionIteratorWithIndex.h>
#include <vtkCellArray.h>
#include <vtkIdList.h>

#include <cmath>
#include <cstdint>
#include <iostream>
#include <map>

namespace {
using namespace brainshift;

constexpr double sphereCentre = 31.3; // off the voxel grid, so the sphere is no lattice's friend

/// 64 mm of 1 mm voxels (mirrored axes, as the built-in case has them): a sphere of tissue 2.
LabelImage::Pointer sphere(double radius)
{
  auto image = LabelImage::New();
  LabelImage::RegionType region;
  region.SetSize({{64, 64, 64}});
  image->SetRegions(region);
  LabelImage::DirectionType direction;
  direction.SetIdentity();
  direction[0][0] = -1;
  direction[1][1] = -1;
  image->SetDirection(direction);
  image->Allocate();
  image->FillBuffer(1);
  itk::ImageRegionIteratorWithIndex<LabelImage> it(image, region);
  for (; !it.IsAtEnd(); ++it) {
    const auto i = it.GetIndex();
    const double x = i[0] - sphereCentre, y = i[1] - sphereCentre, z = i[2] - sphereCentre;
    if (std::sqrt(x * x + y * y + z * z) <= radius) it.Set(2);
  }
  return image;
}

bool closed(vtkPolyData* surface)
{
  std::map<std::pair<vtkIdType, vtkIdType>, int> edges;
  vtkNew<vtkIdList> ids;
  for (vtkIdType c = 0; c < surface->GetNumberOfCells(); ++c) {
    surface->GetCellPoints(c, ids);
    for (int v = 0; v < 3; ++v) {
      const vtkIdType a = ids->GetId(v), b = ids->GetId((v + 1) % 3);
      edges[{std::min(a, b), std::max(a, b)}] += 1;
    }
  }
  for (const auto& [edge, count] : edges) {
    if (count != 2) return false;
  }
  return surface->GetNumberOfCells() > 0;
}

struct RadialError {
  double mean = 0, max = 0, fractionBeyondOneMm = 0;
};

/// Distances of the surface's points from the sphere of the voxels' volume.
RadialError radialError(vtkPolyData* surface, const LabelImage& image, double voxelMl)
{
  const double radius = std::cbrt(3.0 * voxelMl * 1000.0 / (4.0 * M_PI));
  itk::ContinuousIndex<double, 3> c;
  c.Fill(sphereCentre);
  PhysicalPoint centre;
  image.TransformContinuousIndexToPhysicalPoint(c, centre);
  RadialError e;
  for (vtkIdType p = 0; p < surface->GetNumberOfPoints(); ++p) {
    double x[3];
    surface->GetPoint(p, x);
    const double d = std::abs(std::sqrt((x[0] - centre[0]) * (x[0] - centre[0]) + (x[1] - centre[1]) * (x[1] - centre[1]) +
                                        (x[2] - centre[2]) * (x[2] - centre[2])) - radius);
    e.mean += d / double(surface->GetNumberOfPoints());
    e.max = std::max(e.max, d);
    if (d > 1.0) e.fractionBeyondOneMm += 1.0 / double(surface->GetNumberOfPoints());
  }
  return e;
}
} // namespace

int BoundarySnappingTest(int, char*[])
{
  return brainshift::testing::runTest("BoundarySnappingTest", [] {
    const LabelImage::Pointer ball = sphere(20.0);
    RadialError staircase, snapped;
    for (bool snap : {false, true}) {
      MeshingParameters parameters;
      parameters.resolutionMm = 2.0;
      parameters.labels = {2};
      parameters.snapToBoundaries = snap;
      const LabelMapMesh mesh = meshLabelMap(*ball, parameters);
      const MeshQuality& q = mesh.quality;
      const auto surface = boundarySurface(mesh.mesh, {2});
      const RadialError e = radialError(surface, *ball, q.voxelVolumeMl.at(2));
      (snap ? snapped : staircase) = e;
      const double volumeError = q.meshVolumeMl.at(2) / q.voxelVolumeMl.at(2) - 1;
      std::cout << "sphere, " << (snap ? "snapped" : "lattice") << ": surface off the sphere by " << e.mean << " mm on average, "
                << e.max << " mm at most, " << 100 * e.fractionBeyondOneMm << " % beyond 1 mm; volume " << 100 * volumeError << " %; dihedral " << q.minimumDihedralDegrees << " degrees\n";
      BS_CHECK(q.invertedOrFlat == 0);
      BS_CHECK_MSG(q.minimumDihedralDegrees >= 10.0, q.minimumDihedralDegrees);
      BS_CHECK(closed(surface));
      if (snap) BS_CHECK_MSG(std::abs(volumeError) <= 0.03, volumeError);
    }
    // Within a quarter voxel on average (the voxelised sphere itself is staircased by up to half
    // a voxel), and far better than the lattice's staircase.
    BS_CHECK_MSG(snapped.mean <= 0.25, snapped.mean);
    BS_CHECK_MSG(snapped.fractionBeyondOneMm <= 0.02, snapped.fractionBeyondOneMm); // a few stop short to keep quality
    BS_CHECK_MSG(snapped.mean < 0.5 * staircase.mean, snapped.mean << " against " << staircase.mean);

    // Noisy label map: the sphere with a ventricle and a tumour, 5 % of its voxels flipped to a
    // random tissue (a fixed linear congruential sequence: the same noise on every machine).
    const LabelImage::Pointer noisy = sphere(24.0);
    std::uint64_t state = 2000;
    itk::ImageRegionIteratorWithIndex<LabelImage> it(noisy, noisy->GetLargestPossibleRegion());
    for (; !it.IsAtEnd(); ++it) {
      const auto i = it.GetIndex();
      if (it.Get() != 2) continue;
      if (std::abs(i[2] - sphereCentre) <= 1.5 && std::abs(i[0] - sphereCentre) < 12) it.Set(3); // thin ventricle
      if (std::hypot(i[0] - sphereCentre - 18, i[1] - sphereCentre, i[2] - sphereCentre) <= 6) it.Set(4); // touching
      state = state * 6364136223846793005ull + 1442695040888963407ull;
      if ((state >> 33) % 100 < 5) it.Set(LabelPixel(2 + (state >> 40) % 3));
    }
    MeshingParameters parameters;
    parameters.resolutionMm = 2.0;
    const LabelMapMesh mesh = meshLabelMap(*noisy, parameters);
    const MeshQuality& q = mesh.quality;
    std::cout << "noisy: " << q.nodes << " nodes, dihedral " << q.minimumDihedralDegrees << " to " << q.maximumDihedralDegrees
              << " degrees;";
    for (const auto& [l, ml] : q.meshVolumeMl) std::cout << " tissue " << l << " " << ml << " ml of " << q.voxelVolumeMl.at(l);
    std::cout << '\n';
    BS_CHECK(q.invertedOrFlat == 0);
    BS_CHECK_MSG(q.minimumDihedralDegrees >= 10.0, q.minimumDihedralDegrees);
    BS_CHECK((q.meshVolumeMl.size() == 3));
    BS_CHECK(closed(boundarySurface(mesh.mesh, {2, 3, 4})));
    for (int tissue : {2, 3, 4}) BS_CHECK_MSG(closed(boundarySurface(mesh.mesh, {tissue})), "tissue " << tissue);
    const double parenchyma = q.meshVolumeMl.at(2) / q.voxelVolumeMl.at(2) - 1;
    BS_CHECK_MSG(std::abs(parenchyma) <= 0.05, parenchyma);
  });
}
