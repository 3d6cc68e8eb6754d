// The lattice mesher: every tissue meshed, one conforming mesh (each face shared by at most two
// tetrahedra, every surface closed and outward), no inverted element, volumes against the voxels,
// the built-in brain, and bad input named.
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "LabelMapMesher.h"

#include <itkImageRegionIteratorWithIndex.h>
#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkIdList.h>
#include <vtkPointData.h>

#include <iostream>
#include <map>

namespace {
using namespace brainshift;

LabelImage::Pointer phantom()
{
  // 80 mm of 1 mm voxels: a 30 mm sphere of parenchyma (2), a 2 mm slab of ventricle (3) through
  // it, and a tumour (4) of 9 mm touching the sphere's surface.
  auto image = LabelImage::New();
  LabelImage::RegionType region;
  region.SetSize({{80, 80, 80}});
  image->SetRegions(region);
  image->Allocate();
  image->FillBuffer(0);
  itk::ImageRegionIteratorWithIndex<LabelImage> it(image, region);
  for (; !it.IsAtEnd(); ++it) {
    const auto i = it.GetIndex();
    const double x = i[0] - 40, y = i[1] - 40, z = i[2] - 40;
    const double r = std::sqrt(x * x + y * y + z * z);
    if (r <= 30) it.Set(2);
    if (r <= 20 && std::abs(z) <= 1) it.Set(3);
    if (std::sqrt((x - 21) * (x - 21) + y * y + z * z) <= 9) it.Set(4);
  }
  return image;
}

struct SurfaceCheck {
  bool closed = true;
  double enclosedMl = 0;
};

/// Every edge in exactly two triangles, and the volume the triangles enclose (divergence theorem).
SurfaceCheck checkSurface(vtkPolyData* surface)
{
  SurfaceCheck check;
  std::map<std::pair<vtkIdType, vtkIdType>, int> edges;
  vtkNew<vtkIdList> ids;
  double volume = 0;
  for (vtkIdType c = 0; c < surface->GetNumberOfCells(); ++c) {
    surface->GetCellPoints(c, ids);
    double p[3][3];
    for (int v = 0; v < 3; ++v) surface->GetPoint(ids->GetId(v), p[v]);
    volume += (p[0][0] * (p[1][1] * p[2][2] - p[1][2] * p[2][1]) - p[0][1] * (p[1][0] * p[2][2] - p[1][2] * p[2][0]) +
               p[0][2] * (p[1][0] * p[2][1] - p[1][1] * p[2][0])) / 6.0;
    for (int v = 0; v < 3; ++v) {
      vtkIdType a = ids->GetId(v), b = ids->GetId((v + 1) % 3);
      edges[{std::min(a, b), std::max(a, b)}] += 1;
    }
  }
  for (const auto& [edge, count] : edges) check.closed = check.closed && count == 2;
  check.enclosedMl = volume / 1000.0;
  return check;
}
} // namespace

int LabelMapMesherTest(int, char*[])
{
  return brainshift::testing::runTest("LabelMapMesherTest", [] {
    const LabelImage::Pointer labels = phantom();
    for (double h : {1.5, 2.0, 3.0}) {
      MeshingParameters parameters;
      parameters.resolutionMm = h;
      const LabelMapMesh mesh = meshLabelMap(*labels, parameters);
      const MeshQuality& q = mesh.quality;
      std::cout << h << " mm: " << q.nodes << " nodes, " << q.tetrahedra << " tetrahedra, dihedral " << q.minimumDihedralDegrees
                << " to " << q.maximumDihedralDegrees << " degrees;";
      for (const auto& [l, ml] : q.meshVolumeMl) std::cout << " tissue " << l << " " << ml << " ml of " << q.voxelVolumeMl.at(l);
      std::cout << '\n';
      BS_CHECK(q.invertedOrFlat == 0);
      BS_CHECK_MSG(q.minimumDihedralDegrees >= 10.0, q.minimumDihedralDegrees);
      BS_CHECK((q.meshVolumeMl.size() == 3)); // every tissue present
      // Boundary nodes on the label boundaries: every tissue's volume within 3 % of its voxels'
      // at 1.5 mm, also the thin ventricle and the tumour touching the surface (at 2 mm the
      // tumour's 9 mm radius spans four edges, and its junction with the surface costs ~5 %).
      for (int tissue : {2, 3, 4}) {
        if (h > 2.0 || (h > 1.5 && tissue == 4)) continue;
        const double ratio = q.meshVolumeMl.at(tissue) / q.voxelVolumeMl.at(tissue);
        BS_CHECK_MSG(std::abs(ratio - 1) <= 0.03, "tissue " << tissue << " volume off by " << ratio - 1 << " at " << h << " mm");
      }
      // One conforming mesh: no face in more than two tetrahedra; the whole and each tissue closed.
      const auto whole = boundarySurface(mesh.mesh, {2, 3, 4});
      const SurfaceCheck wholeCheck = checkSurface(whole);
      BS_CHECK(wholeCheck.closed);
      double meshMl = 0;
      for (const auto& [l, ml] : q.meshVolumeMl) meshMl += ml;
      BS_CHECK_NEAR(wholeCheck.enclosedMl, meshMl, 1e-6 * meshMl); // outward: the enclosed volume is the mesh's
      for (int tissue : {2, 3, 4}) {
        const auto surface = boundarySurface(mesh.mesh, {tissue});
        const SurfaceCheck c = checkSurface(surface);
        BS_CHECK_MSG(c.closed, "tissue " << tissue << " at " << h << " mm");
        BS_CHECK_NEAR(c.enclosedMl, q.meshVolumeMl.at(tissue), 1e-6 * q.meshVolumeMl.at(tissue) + 1e-9);
      }
      // Each surface point is the mesh node it names.
      vtkDataArray* ids = whole->GetPointData()->GetArray("MeshNodeId");
      for (vtkIdType p = 0; p < whole->GetNumberOfPoints(); p += 97) {
        double a[3], b[3];
        whole->GetPoint(p, a);
        mesh.mesh->GetPoint(vtkIdType(ids->GetComponent(p, 0)), b);
        BS_CHECK(a[0] == b[0] && a[1] == b[1] && a[2] == b[2]);
      }
    }

    // A detached fragment of parenchyma (a 6 mm cube in a corner) is not part of the model: no
    // boundary condition would hold it, and the stiffness matrix would be singular. It is dropped,
    // with a warning, and the mesh is the sphere alone.
    {
      const LabelImage::Pointer withFragment = phantom();
      for (int k = 66; k < 72; ++k) {
        for (int j = 66; j < 72; ++j) {
          for (int i = 66; i < 72; ++i) {
            LabelImage::IndexType voxel;
            voxel[0] = i;
            voxel[1] = j;
            voxel[2] = k;
            withFragment->SetPixel(voxel, 2);
          }
        }
      }
      MeshingParameters parameters;
      parameters.resolutionMm = 2.0;
      const LabelMapMesh clean = meshLabelMap(*labels, parameters);
      const LabelMapMesh mesh = meshLabelMap(*withFragment, parameters);
      bool warned = false;
      for (const std::string& w : mesh.warnings) warned = warned || w.find("were dropped") != std::string::npos;
      for (const std::string& w : clean.warnings) BS_CHECK_MSG(w.find("were dropped") == std::string::npos, w);
      BS_CHECK(warned);
      BS_CHECK_MSG(mesh.quality.nodes == clean.quality.nodes && mesh.quality.tetrahedra == clean.quality.tetrahedra,
                   mesh.quality.nodes << " nodes against " << clean.quality.nodes);
      BS_CHECK(checkSurface(boundarySurface(mesh.mesh, {2, 3, 4})).closed);
    }

    // The built-in brain (small case, 2 mm labels) at 3 mm with the image's mirrored directions.
    CaseParameters small;
    small.size = CaseSize::Small;
    const SimulatedCase c = simulateCase(small);
    MeshingParameters brain;
    brain.resolutionMm = 3.0;
    const LabelMapMesh brainMesh = meshLabelMap(*c.preopLabels, brain);
    std::cout << "brain at 3 mm: " << brainMesh.quality.nodes << " nodes (" << 3 * brainMesh.quality.nodes << " equations), "
              << brainMesh.quality.tetrahedra << " tetrahedra\n";
    BS_CHECK(brainMesh.quality.invertedOrFlat == 0);
    BS_CHECK(checkSurface(boundarySurface(brainMesh.mesh, {2, 3, 4})).closed);

    // Bad input.
    MeshingParameters parameters;
    parameters.resolutionMm = 0.5;
    BS_CHECK_THROWS(meshLabelMap(*labels, parameters), InputError, "finer than the label map's voxels");
    parameters.resolutionMm = 40.0;
    BS_CHECK_THROWS(meshLabelMap(*labels, parameters), InputError, "absurdly coarse");
    parameters.resolutionMm = 2.0;
    parameters.labels = {2, 7};
    BS_CHECK_THROWS(meshLabelMap(*labels, parameters), InputError, "tissue label 7 is not in the label map");
    auto zeros = LabelImage::New();
    zeros->CopyInformation(labels);
    zeros->SetRegions(labels->GetLargestPossibleRegion());
    zeros->Allocate();
    zeros->FillBuffer(0);
    parameters.labels = {2, 3, 4};
    BS_CHECK_THROWS(meshLabelMap(*zeros, parameters), InputError, "holds none of the tissues");
    // A tissue of one voxel vanishes at 6 mm: named, not silently missing.
    zeros->FillBuffer(2);
    zeros->SetPixel({{41, 41, 41}}, 4);
    parameters.resolutionMm = 6.0;
    parameters.labels = {2, 4};
    BS_CHECK_THROWS(meshLabelMap(*zeros, parameters), InputError, "tissue label 4");
  });
}
