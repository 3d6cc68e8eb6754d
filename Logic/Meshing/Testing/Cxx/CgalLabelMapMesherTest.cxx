// The CGAL Mesh_3 backend: every tissue meshed, closed outward surfaces per tissue and for the
// union, no inverted element, the same run twice gives the same mesh, and bad input named as the
// lattice names it. Without CGAL: a clear NotAvailableError.
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "CgalLabelMapMesher.h"
#include "LabelMapMesher.h"

#include <itkImageRegionIteratorWithIndex.h>
#include <vtkIdList.h>

#include <cmath>
#include <iostream>
#include <map>

namespace {
using namespace brainshift;

/// 56 mm of 1 mm voxels, mirrored axes: a sphere of parenchyma (2) with a 3 mm slab of ventricle
/// (3) and a tumour (4) touching its surface.
LabelImage::Pointer phantom()
{
  auto image = LabelImage::New();
  LabelImage::RegionType region;
  region.SetSize({{56, 56, 56}});
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
    const double x = i[0] - 27.6, y = i[1] - 27.6, z = i[2] - 27.6;
    if (std::sqrt(x * x + y * y + z * z) <= 22) it.Set(2);
    if (std::sqrt(x * x + y * y + z * z) <= 14 && std::abs(z) <= 1.5) it.Set(3);
    if (std::sqrt((x - 16) * (x - 16) + y * y + z * z) <= 6) it.Set(4);
  }
  return image;
}

/// The share of boundary edges not shared by exactly two triangles (0: closed and manifold).
double nonManifoldEdgeFraction(vtkPolyData* surface)
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
  std::size_t bad = 0;
  for (const auto& [edge, count] : edges) bad += count != 2;
  return edges.empty() ? 1.0 : double(bad) / double(edges.size());
}

bool closed(vtkPolyData* surface) { return surface->GetNumberOfCells() > 0 && nonManifoldEdgeFraction(surface) == 0; }
} // namespace

int CgalLabelMapMesherTest(int, char*[])
{
  return brainshift::testing::runTest("CgalLabelMapMesherTest", [] {
    const LabelImage::Pointer labels = phantom();
    MeshingParameters parameters;
    parameters.backend = MeshingBackend::Cgal;
    parameters.resolutionMm = 3.0;
    if (!cgalMeshingAvailable()) {
      BS_CHECK_THROWS(meshLabelMap(*labels, parameters), NotAvailableError, "built without CGAL");
      std::cout << "built without CGAL: NotAvailableError checked\n";
      return;
    }
    const LabelMapMesh mesh = meshLabelMap(*labels, parameters);
    const MeshQuality& q = mesh.quality;
    std::cout << "CGAL at 3 mm: " << q.nodes << " nodes, " << q.tetrahedra << " tetrahedra, dihedral " << q.minimumDihedralDegrees
              << " to " << q.maximumDihedralDegrees << " degrees;";
    for (const auto& [l, ml] : q.meshVolumeMl) std::cout << " tissue " << l << " " << ml << " ml of " << q.voxelVolumeMl.at(l);
    std::cout << '\n';
    BS_CHECK(q.invertedOrFlat == 0);
    BS_CHECK((q.meshVolumeMl.size() == 3)); // every tissue, and no other label (background is not meshed)
    BS_CHECK(closed(boundarySurface(mesh.mesh, {2, 3, 4})));
    for (int tissue : {2, 3, 4}) {
      // CGAL 5.5 guarantees manifold tissue interfaces only with manifold(), which does not end
      // on several tissues without protected junctions: a few junction edges stay non-manifold.
      const double open = nonManifoldEdgeFraction(boundarySurface(mesh.mesh, {tissue}));
      std::cout << "  tissue " << tissue << ": " << 100 * open << " % of its boundary edges non-manifold\n";
      BS_CHECK_MSG(open < 0.02, "tissue " << tissue << " " << open);
      const double ratio = q.meshVolumeMl.at(tissue) / q.voxelVolumeMl.at(tissue);
      BS_CHECK_MSG(std::abs(ratio - 1) <= 0.15, "tissue " << tissue << " volume off by " << ratio - 1);
    }
    // LPS: the mesh lies where the voxels are (the image's axes are mirrored).
    double bounds[6];
    mesh.mesh->GetBounds(bounds);
    BS_CHECK_MSG(bounds[0] > -52 && bounds[1] < -3 && bounds[2] > -52 && bounds[3] < -3 && bounds[4] > 3 && bounds[5] < 52,
                 bounds[0] << " " << bounds[1] << " " << bounds[4] << " " << bounds[5]);
    // Reproducible.
    const LabelMapMesh again = meshLabelMap(*labels, parameters);
    BS_CHECK(again.quality.nodes == q.nodes && again.quality.tetrahedra == q.tetrahedra);
    bool same = true;
    for (vtkIdType p = 0; p < mesh.mesh->GetNumberOfPoints() && same; ++p) {
      double a[3], b[3];
      mesh.mesh->GetPoint(p, a);
      again.mesh->GetPoint(p, b);
      same = a[0] == b[0] && a[1] == b[1] && a[2] == b[2];
    }
    BS_CHECK(same);

    // Bad input, as the lattice reports it.
    auto zeros = LabelImage::New();
    zeros->CopyInformation(labels);
    zeros->SetRegions(labels->GetLargestPossibleRegion());
    zeros->Allocate();
    zeros->FillBuffer(0);
    BS_CHECK_THROWS(meshLabelMap(*zeros, parameters), InputError, "holds none of the tissues");
    parameters.resolutionMm = 0.2;
    BS_CHECK_THROWS(meshLabelMap(*labels, parameters), InputError, "finer than the label map's voxels");
  });
}
