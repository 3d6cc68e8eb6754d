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

#include <array>
#include <atomic>
#include <cmath>
#include <iostream>
#include <map>
#include <set>

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

    // Graded: fine at every tissue interface and the outer surface, coarser inside. The same
    // guarantees as the uniform lattice, with fewer nodes, and no hanging node.
    for (double h : {1.5, 2.0}) {
      MeshingParameters uniform;
      uniform.resolutionMm = h;
      MeshingParameters graded = uniform;
      graded.gradingRate = 1.0;
      const LabelMapMesh u = meshLabelMap(*labels, uniform);
      const LabelMapMesh g = meshLabelMap(*labels, graded);
      const MeshQuality& q = g.quality;
      std::cout << "graded " << h << " mm: " << q.nodes << " nodes (uniform " << u.quality.nodes << "), dihedral "
                << q.minimumDihedralDegrees << " to " << q.maximumDihedralDegrees << " degrees;";
      for (const auto& [l, ml] : q.meshVolumeMl) std::cout << " tissue " << l << " " << ml << " ml of " << q.voxelVolumeMl.at(l);
      std::cout << '\n';
      // A small phantom, mostly interface: 26 % fewer nodes at 1.5 mm, 18 % at 2 mm.
      BS_CHECK_MSG(double(q.nodes) < (h < 2 ? 0.8 : 0.9) * double(u.quality.nodes), q.nodes << " nodes against " << u.quality.nodes);
      BS_CHECK(q.invertedOrFlat == 0);
      BS_CHECK_MSG(q.minimumDihedralDegrees >= 10.0, q.minimumDihedralDegrees);
      BS_CHECK((q.meshVolumeMl.size() == 3));
      // The bisected lattice's cubes alternate their diagonals; the 3-voxel ventricle slab then
      // loses 5 % at 2 mm (0.5 % on the uniform lattice), within 3 % at 1.5 mm.
      for (int tissue : {2, 3, 4}) {
        if (h > 1.5 && tissue != 2) continue;
        const double ratio = q.meshVolumeMl.at(tissue) / q.voxelVolumeMl.at(tissue);
        BS_CHECK_MSG(std::abs(ratio - 1) <= 0.03, "graded: tissue " << tissue << " volume off by " << ratio - 1 << " at " << h << " mm");
      }
      BS_CHECK(checkSurface(boundarySurface(g.mesh, {2, 3, 4})).closed);
      for (int tissue : {2, 3, 4}) BS_CHECK_MSG(checkSurface(boundarySurface(g.mesh, {tissue})).closed, "graded: tissue " << tissue);
    }
    {
      // No node inside another element's edge (a hanging node would leave the surfaces closed
      // but the mesh torn): checked on the unsnapped lattice, where positions are exact.
      MeshingParameters graded;
      graded.resolutionMm = 2.0;
      graded.gradingRate = 1.0;
      graded.snapToBoundaries = false;
      const LabelMapMesh g = meshLabelMap(*labels, graded);
      std::set<std::array<long long, 3>> nodes;
      auto key = [](const double x[3]) {
        return std::array<long long, 3>{std::llround(x[0] * 1e4), std::llround(x[1] * 1e4), std::llround(x[2] * 1e4)};
      };
      for (vtkIdType v = 0; v < g.mesh->GetNumberOfPoints(); ++v) nodes.insert(key(g.mesh->GetPoint(v)));
      std::size_t hanging = 0;
      vtkNew<vtkIdList> ids;
      for (vtkIdType c = 0; c < g.mesh->GetNumberOfCells(); ++c) {
        g.mesh->GetCellPoints(c, ids);
        for (int a = 0; a < 4; ++a) {
          for (int b = a + 1; b < 4; ++b) {
            double p[3], q[3], m[3];
            g.mesh->GetPoint(ids->GetId(a), p);
            g.mesh->GetPoint(ids->GetId(b), q);
            for (int d = 0; d < 3; ++d) m[d] = 0.5 * (p[d] + q[d]);
            hanging += nodes.count(key(m));
          }
        }
      }
      BS_CHECK_MSG(hanging == 0, hanging << " element edges hold a node at their midpoint");
    }
    {
      // A region of interest deep in the parenchyma (11 mm from the ventricle, 18 mm from the
      // surface): coarse without it, at the resolution with it.
      MeshingParameters graded;
      graded.resolutionMm = 2.0;
      graded.gradingRate = 1.0;
      const std::array<double, 3> centre{40, 40, 28}; // 1 mm voxels at the origin: index = LPS mm
      auto longestEdgeNear = [&](const LabelMapMesh& m) {
        double longest = 0;
        vtkNew<vtkIdList> ids;
        for (vtkIdType c = 0; c < m.mesh->GetNumberOfCells(); ++c) {
          m.mesh->GetCellPoints(c, ids);
          double p[4][3], centroid[3] = {0, 0, 0};
          for (int v = 0; v < 4; ++v) {
            m.mesh->GetPoint(ids->GetId(v), p[v]);
            for (int d = 0; d < 3; ++d) centroid[d] += 0.25 * p[v][d];
          }
          double r2 = 0;
          for (int d = 0; d < 3; ++d) r2 += (centroid[d] - centre[std::size_t(d)]) * (centroid[d] - centre[std::size_t(d)]);
          if (r2 > 16.0) continue;
          for (int a = 0; a < 4; ++a) {
            for (int b = a + 1; b < 4; ++b) {
              double e2 = 0;
              for (int d = 0; d < 3; ++d) e2 += (p[a][d] - p[b][d]) * (p[a][d] - p[b][d]);
              longest = std::max(longest, std::sqrt(e2));
            }
          }
        }
        return longest;
      };
      const double without = longestEdgeNear(meshLabelMap(*labels, graded));
      graded.regionOfInterest = MeshingParameters::Sphere{centre, 5.0};
      const double with = longestEdgeNear(meshLabelMap(*labels, graded));
      std::cout << "region of interest: longest edge " << with << " mm (" << without << " mm without)\n";
      BS_CHECK_MSG(without > 2.0 * std::sqrt(3.0) + 0.1, without);
      BS_CHECK_MSG(with <= 2.0 * std::sqrt(3.0) + 1e-6, with);
      graded.regionOfInterest->radiusMm = -1;
      BS_CHECK_THROWS(meshLabelMap(*labels, graded), InputError, "positive radius");
      graded.regionOfInterest.reset();
      graded.gradingRate = -0.5;
      BS_CHECK_THROWS(meshLabelMap(*labels, graded), InputError, "mesh grading -0.5");
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

    // Cancelled (the host's Cancel): CancelledError, no mesh.
    {
      std::atomic<bool> cancel{true};
      MeshingParameters cancelled;
      cancelled.cancel = &cancel;
      BS_CHECK_THROWS(meshLabelMap(*labels, cancelled), CancelledError, "meshing cancelled");
    }

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
    BS_CHECK_THROWS(meshLabelMap(*zeros, parameters), InputError, "vanishes at 6 mm"); // as given, not 6.000000
  });
}
