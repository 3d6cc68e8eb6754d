// The boundary the field shows where the brain sank: a box of brain whose top sinks 6 mm (and 20 mm) while its
// bottom stays (u_z falling linearly with depth, exact inside the mesh), seen on a grid of 2.5 mm
// slices. Above the sunken top face the mapping must show the preoperative space above the brain,
// so the boundary the warped labels show is the deformed face (within half a millimetre). The fade
// alone (continuationMaximumMm 0) averages the smaller corrections deeper inside and shows the
// boundary more than a millimetre too high: the failure the continuation fixes. Neither folds; a
// band too narrow for the sink folds outside the mesh only, and the folds are counted apart. In a
// trench whose walls sank above a floor that did not, the continuation takes the walls'
// correction, nearer in millimetres, not the floor's, nearer in steps across thick slices; and on
// spacings no float holds exactly the voxels next to the mesh are continued too.
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "DeformationField.h"
#include "SyntheticData.h"

#include <itkIdentityTransform.h>
#include <itkImageRegionConstIteratorWithIndex.h>
#include <itkImageRegionIteratorWithIndex.h>
#include <vtkDoubleArray.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkSmartPointer.h>
#include <vtkUnstructuredGrid.h>

#include <algorithm>
#include <cmath>
#include <iostream>

namespace {
using namespace brainshift;
using brainshift::testing::point;

constexpr double BoxTop = 20.0, BoxBottom = -20.0;

/// The box [-20, 20] mm squared by [bottom, 20] mm tall in cubes of 4 mm, each cut into the six
/// tetrahedra about its diagonal (Kuhn): a conforming mesh with flat faces. `trenchLayers` > 0
/// leaves out the two columns of cubes about x = 0 in that many top layers: a trench 8 mm wide
/// along y.
vtkSmartPointer<vtkUnstructuredGrid> kuhnBox(double bottom, int trenchLayers = 0)
{
  constexpr int cells = 10;
  constexpr double step = (BoxTop - BoxBottom) / cells;
  const int layers = int(std::lround((BoxTop - bottom) / step));
  auto mesh = vtkSmartPointer<vtkUnstructuredGrid>::New();
  vtkNew<vtkPoints> points;
  auto node = [](int i, int j, int k) { return vtkIdType(i + (cells + 1) * (j + (cells + 1) * k)); };
  for (int k = 0; k <= layers; ++k)
    for (int j = 0; j <= cells; ++j)
      for (int i = 0; i <= cells; ++i) points->InsertNextPoint(BoxBottom + step * i, BoxBottom + step * j, bottom + step * k);
  mesh->SetPoints(points);
  const int orders[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = 0; k < layers; ++k)
    for (int j = 0; j < cells; ++j)
      for (int i = 0; i < cells; ++i) {
        if (k >= layers - trenchLayers && (i == cells / 2 - 1 || i == cells / 2)) continue;
        for (const auto& order : orders) {
          int corner[3] = {i, j, k};
          vtkIdType ids[4] = {node(i, j, k), 0, 0, 0};
          for (int v = 0; v < 3; ++v) {
            corner[order[v]] += 1;
            ids[v + 1] = node(corner[0], corner[1], corner[2]);
          }
          mesh->InsertNextCell(VTK_TETRA, 4, ids);
        }
      }
  return mesh;
}

/// `mesh` with the point array "Displacement": a sink u_z = -sinkOf(z) at each node's height z.
template <typename SinkOf>
vtkSmartPointer<vtkUnstructuredGrid> sinking(vtkSmartPointer<vtkUnstructuredGrid> mesh, SinkOf&& sinkOf)
{
  vtkNew<vtkDoubleArray> displacement;
  displacement->SetName("Displacement");
  displacement->SetNumberOfComponents(3);
  for (vtkIdType i = 0; i < mesh->GetNumberOfPoints(); ++i) {
    double x[3];
    mesh->GetPoint(i, x);
    const double u[3] = {0.0, 0.0, -sinkOf(x[2])};
    displacement->InsertNextTuple(u);
  }
  mesh->GetPointData()->AddArray(displacement);
  return mesh;
}

constexpr double TrenchFloor = 8.0; ///< three 4 mm layers below BoxTop

/// The box with the trench, whose tissue above the trench's floor sinks the more the higher it
/// lies (its top by `sinkMm`), the floor and all below it not at all.
vtkSmartPointer<vtkUnstructuredGrid> trenchedBox(double sinkMm)
{
  return sinking(kuhnBox(BoxBottom, 3),
                 [sinkMm](double z) { return sinkMm * std::max(0.0, z - TrenchFloor) / (BoxTop - TrenchFloor); });
}

/// The box from `bottom` up whose top sinks `sinkMm` while its bottom stays (u_z falling linearly with depth).
vtkSmartPointer<vtkUnstructuredGrid> sinkingBox(double sinkMm, double bottom = BoxBottom)
{
  return sinking(kuhnBox(bottom), [sinkMm, bottom](double z) { return sinkMm * (z - bottom) / (BoxTop - bottom); });
}

/// The correction x_z - y_z that tissue sinking by `share` of its height above `still` shows at the
/// deformed height y_z: the preoperative x_z with x_z - share (x_z - still) = y_z.
double sinkCorrectionAt(double yz, double share, double still)
{
  return (yz - share * still) / (1.0 - share) - yz;
}

/// The height where the field shows the preoperative top face (X_z = BoxTop), along the column of
/// the grid's voxels (i, j): interpolated between the last slice that shows brain and the next.
double shownTopFace(const DeformationField& f, long i, long j)
{
  const auto size = f.field->GetLargestPossibleRegion().GetSize();
  double previousY = 0, previousX = 0;
  for (long k = 0; k < long(size[2]); ++k) {
    PhysicalPoint y;
    f.field->TransformIndexToPhysicalPoint({{i, j, k}}, y);
    const double x = y[2] + f.field->GetPixel({{i, j, k}})[2];
    if (k > 0 && previousX < BoxTop && x >= BoxTop) return previousY + (BoxTop - previousX) / (x - previousX) * (y[2] - previousY);
    previousY = y[2];
    previousX = x;
  }
  return std::nan("");
}

/// The shown top face over the columns within 10 mm of the box's axis: the worst distance from the
/// deformed face (BoxTop - sinkMm) and the mean signed one (positive: too high).
void measureTopFace(const DeformationField& f, double sinkMm, double& worst, double& meanSigned)
{
  const auto size = f.field->GetLargestPossibleRegion().GetSize();
  worst = 0;
  double sum = 0;
  std::size_t columns = 0;
  for (long j = 0; j < long(size[1]); ++j) {
    for (long i = 0; i < long(size[0]); ++i) {
      PhysicalPoint y;
      f.field->TransformIndexToPhysicalPoint({{i, j, 0}}, y);
      if (std::abs(y[0] - 1.0) > 10 || std::abs(y[1] - 1.0) > 10) continue;
      const double error = shownTopFace(f, i, j) - (BoxTop - sinkMm);
      worst = std::max(worst, std::abs(error));
      sum += error;
      ++columns;
    }
  }
  BS_CHECK_MSG(columns > 100, columns << " columns measured");
  meanSigned = sum / double(columns);
}
} // namespace

int DeformationFieldBoundaryTest(int, char*[])
{
  return brainshift::testing::runTest("DeformationFieldBoundaryTest", [] {
    const vtkSmartPointer<vtkUnstructuredGrid> mesh = sinkingBox(6.0);
    const auto identity = itk::IdentityTransform<double, 3>::New();
    const ImageGeometry grid = brainshift::testing::grid({{60, 60, 28}}, {1.0, 1.0, 2.5}, point(-29, -29, -29.5));

    const DeformationField continued = intraopToPreopField(mesh, *identity, grid, {}, "mesh.vtu");
    DeformationFieldParameters fadeOnly;
    fadeOnly.continuationMaximumMm = 0;
    const DeformationField faded = intraopToPreopField(mesh, *identity, grid, fadeOnly, "mesh.vtu");
    double worstContinued = 0, meanContinued = 0, worstFaded = 0, meanFaded = 0;
    measureTopFace(continued, 6.0, worstContinued, meanContinued);
    measureTopFace(faded, 6.0, worstFaded, meanFaded);
    std::cout << "shown top face, continued: worst " << worstContinued << " mm, mean " << meanContinued << " mm (band "
              << continued.continuationBandMm << " mm, " << continued.continuedVoxels << " voxels, " << continued.foldedVoxels
              << " folded, min Jacobian " << continued.minimumJacobian << "); fade alone: worst " << worstFaded << " mm, mean "
              << meanFaded << " mm (" << faded.foldedVoxels << " folded)\n";
    BS_CHECK_MSG(worstContinued < 0.5, "the continued field shows the sunken face " << worstContinued << " mm off");
    BS_CHECK_MSG(meanFaded > 1.0, "the fade alone shows the face only " << meanFaded << " mm too high: the test no longer tells");
    BS_CHECK(continued.continuationBandMm >= 3.0 && continued.continuationBandMm <= 15.0);
    BS_CHECK(continued.continuedVoxels > 1000 && faded.continuedVoxels == 0);
    BS_CHECK_MSG(continued.foldedVoxels == 0 && continued.minimumJacobian > 0.1, continued.foldedVoxels << " folded, min "
                                                                                  << continued.minimumJacobian);
    BS_CHECK(faded.foldedVoxels == 0);
    // A band narrower than the sink (4 mm for 6) compresses the space above the face past zero: the
    // field folds there, outside the mesh, and the folds are told apart from the brain's (none).
    DeformationFieldParameters narrow;
    narrow.continuationMaximumMm = 4.0;
    const DeformationField squeezed = intraopToPreopField(mesh, *identity, grid, narrow, "mesh.vtu");
    std::cout << "band of " << squeezed.continuationBandMm << " mm: " << squeezed.foldedVoxels << " folded, "
              << squeezed.foldedVoxelsInMesh << " of them in the mesh\n";
    BS_CHECK_MSG(squeezed.foldedVoxels >= 50, squeezed.foldedVoxels << " folded: the narrow band no longer folds");
    BS_CHECK_MSG(squeezed.foldedVoxelsInMesh == 0, squeezed.foldedVoxelsInMesh << " folded in the mesh");
    // A 20 mm sink, the scenarios' deepest: the band widens to take it at 2/3 compression (30 mm
    // at most), the face is shown where it sank and nothing folds. Capped at 15 mm, as it was, the
    // band folded the gap above the face (on the 20 mm scenarios it showed preoperative brain up to
    // 16 mm above the sunken one there).
    const vtkSmartPointer<vtkUnstructuredGrid> deepMesh = sinkingBox(20.0, -100.0);
    const ImageGeometry tallGrid = brainshift::testing::grid({{60, 60, 60}}, {1.0, 1.0, 2.5}, point(-29, -29, -109.5));
    const DeformationField deep = intraopToPreopField(deepMesh, *identity, tallGrid, {}, "mesh.vtu");
    DeformationFieldParameters formerCap;
    formerCap.continuationMaximumMm = 15.0;
    const DeformationField capped = intraopToPreopField(deepMesh, *identity, tallGrid, formerCap, "mesh.vtu");
    double worstDeep = 0, meanDeep = 0;
    measureTopFace(deep, 20.0, worstDeep, meanDeep);
    std::cout << "20 mm sink: shown top face worst " << worstDeep << " mm, mean " << meanDeep << " mm (band " << deep.continuationBandMm
              << " mm, " << deep.foldedVoxels << " folded, min Jacobian " << deep.minimumJacobian << "); band capped at 15 mm: "
              << capped.foldedVoxels << " folded\n";
    BS_CHECK_MSG(worstDeep < 0.5, "the 20 mm sink's face shown " << worstDeep << " mm off");
    BS_CHECK(deep.continuationBandMm > 20.0 && deep.continuationBandMm <= 30.0);
    BS_CHECK_MSG(deep.foldedVoxels == 0, deep.foldedVoxels << " folded");
    BS_CHECK_MSG(capped.foldedVoxels > 0, "a 15 mm band no longer folds a 20 mm sink: the test no longer tells");
    // The continuation takes the nearest tissue's correction in millimetres, not in steps. In a
    // trench 8 mm wide whose walls sank (their top by 3 mm) above a floor that did not, on slices
    // 2.5 mm thick and 0.5 mm in plane, a voxel in the trench's middle lies 4 mm (8 steps) from
    // the walls and 5-8 mm (2-3 steps) above the floor: counted in steps it took the floor's
    // correction (none), and the warped volumes showed preoperative tissue in the trench.
    constexpr double trenchSinkMm = 3.0;
    const vtkSmartPointer<vtkUnstructuredGrid> trenched = trenchedBox(trenchSinkMm);
    const ImageGeometry fineGrid = brainshift::testing::grid({{60, 60, 24}}, {0.5, 0.5, 2.5}, point(-14.75, -14.75, -29.5));
    DeformationFieldParameters wideBand; // the band's blend into the fade kept small (t <= 1.5 / 30)
    wideBand.continuationMinimumMm = 30.0;
    const DeformationField trench = intraopToPreopField(trenched, *identity, fineGrid, wideBand, "mesh.vtu");
    const double sinkShare = trenchSinkMm / (BoxTop - TrenchFloor);
    double worstShare = 1, sumShare = 0;
    std::size_t trenchVoxels = 0;
    for (itk::ImageRegionConstIteratorWithIndex<DisplacementFieldImage> it(trench.field, trench.field->GetLargestPossibleRegion());
         !it.IsAtEnd(); ++it) {
      PhysicalPoint y;
      trench.field->TransformIndexToPhysicalPoint(it.GetIndex(), y);
      if (std::abs(y[0]) > 3.0 || std::abs(y[1]) > 10.0 || y[2] < TrenchFloor + 4.5 || y[2] > BoxTop - trenchSinkMm - 0.5) continue;
      const double wall = sinkCorrectionAt(y[2], sinkShare, TrenchFloor); // the walls' at this height
      const double share = it.Get()[2] / wall;
      worstShare = std::min(worstShare, share);
      sumShare += share;
      ++trenchVoxels;
    }
    BS_CHECK_MSG(trenchVoxels > 200, trenchVoxels << " voxels in the trench");
    std::cout << "trench: the continued correction " << sumShare / double(trenchVoxels) << " of the walls' on average, "
              << worstShare << " at least, over " << trenchVoxels << " voxels\n";
    BS_CHECK_MSG(worstShare > 0.75 && sumShare / double(trenchVoxels) > 0.85,
                 "in the trench the continuation gives " << worstShare << " of the walls' correction (mean "
                                                         << sumShare / double(trenchVoxels) << "): the floor's, nearer in steps");
    // Spacings no float holds exactly (0.7 mm: float(0.7) < 0.7) take the same path: every voxel
    // next to the mesh is continued, none is left to the fade by a distance rounded down a shell.
    const ImageGeometry oddGrid = brainshift::testing::grid({{84, 84, 26}}, {0.7, 0.7, 2.3}, point(-29.05, -29.05, -29.9));
    const DeformationField odd = intraopToPreopField(mesh, *identity, oddGrid, {}, "mesh.vtu");
    double worstOdd = 0, meanOdd = 0;
    measureTopFace(odd, 6.0, worstOdd, meanOdd);
    std::cout << "0.7 x 0.7 x 2.3 mm voxels: shown top face worst " << worstOdd << " mm (" << odd.continuedVoxels
              << " voxels continued)\n";
    BS_CHECK_MSG(worstOdd < 0.5, "on 0.7 mm voxels the face is shown " << worstOdd << " mm off");
    // Beside the box's side walls (|x| just over 20 mm) the wall's correction continues: the first
    // in-plane layer, 0.7 mm out, is a step of the shortest spacing from the mesh.
    double sideShare = 0;
    std::size_t sideVoxels = 0;
    for (itk::ImageRegionConstIteratorWithIndex<DisplacementFieldImage> it(odd.field, odd.field->GetLargestPossibleRegion()); !it.IsAtEnd();
         ++it) {
      PhysicalPoint y;
      odd.field->TransformIndexToPhysicalPoint(it.GetIndex(), y);
      if (std::abs(y[0]) <= BoxTop || std::abs(y[0]) > BoxTop + 0.7 || std::abs(y[1]) > 10.0 || y[2] < -10.0 || y[2] > 8.0) continue;
      const double wall = sinkCorrectionAt(y[2], 6.0 / (BoxTop - BoxBottom), BoxBottom); // the walls' at this height
      sideShare += it.Get()[2] / wall;
      ++sideVoxels;
    }
    BS_CHECK_MSG(sideVoxels > 100, sideVoxels << " voxels beside the walls");
    std::cout << "beside the walls on 0.7 mm voxels: " << sideShare / double(sideVoxels) << " of the walls' correction over "
              << sideVoxels << " voxels\n";
    BS_CHECK_MSG(sideShare / double(sideVoxels) > 0.95, "beside the walls the continuation gives " << sideShare / double(sideVoxels)
                                                                                                   << " of the walls' correction");
    DeformationFieldParameters absurd;
    absurd.continuationMaximumCompression = 0;
    BS_CHECK_THROWS(intraopToPreopField(mesh, *identity, grid, absurd, "mesh.vtu"), InputError, "continuation");
    absurd = {};
    absurd.continuationMinimumMm = 40;
    BS_CHECK_THROWS(intraopToPreopField(mesh, *identity, grid, absurd, "mesh.vtu"), InputError, "minimum <= maximum");
  });
}
