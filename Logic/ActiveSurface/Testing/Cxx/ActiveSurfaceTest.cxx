// The active surface: a sphere that shrinks under a rigid motion (the surface lands on the target
// sphere, moves radially, honours the rigid transform), the small built-in case against its truth,
// a resected tumour left free, the membrane kept for its own mesh alone, a deep sink's bottom
// reached, determinism, and bad input named.
#include "ActiveSurfaceLogic.h"
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "Configuration.h"
#include "LabelMapMesher.h"
#include "SurfaceDisplacementEvaluation.h"
#include "SyntheticData.h"

#include <itkImageRegionIteratorWithIndex.h>
#include <vtkCellData.h>
#include <vtkDataArray.h>
#include <vtkIntArray.h>
#include <vtkPoints.h>
#include <vtkUnstructuredGrid.h>
#include <vtkPointData.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <iostream>
#include <utility>
#include <vector>

namespace {
using namespace brainshift;
using brainshift::testing::point;

const PhysicalPoint sphereCentre = point(2.0, -4.0, 6.0);

/// Labels on `geometry`: parenchyma (2) within `radius` mm of the centre (seen through
/// `intraopToPreop`, so the content is where that transform says), and a tumour (4) of 9 mm at the
/// top touching the surface unless `resected`.
LabelImage::Pointer sphereLabels(const ImageGeometry& geometry, double radius, const SpatialTransform* intraopToPreop,
                                 bool tumour, bool resected)
{
  auto image = brainshift::testing::makeImage<LabelImage>(geometry);
  itk::ImageRegionIteratorWithIndex<LabelImage> it(image, image->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint y;
    image->TransformIndexToPhysicalPoint(it.GetIndex(), y);
    const PhysicalPoint x = intraopToPreop ? intraopToPreop->TransformPoint(y) : y;
    const double r = x.EuclideanDistanceTo(sphereCentre);
    LabelPixel label = r <= radius ? 2 : 0;
    PhysicalPoint top = sphereCentre;
    top[2] += radius - 4.0;
    if (tumour && x.EuclideanDistanceTo(top) <= 9.0) label = resected ? 0 : 4;
    it.Set(label);
  }
  return image;
}

ScalarImage::Pointer intensityOf(const LabelImage& labels)
{
  auto image = brainshift::testing::makeImage<ScalarImage>(ImageGeometry::of(&labels));
  const LabelPixel* l = labels.GetBufferPointer();
  float* v = image->GetBufferPointer();
  for (std::size_t i = 0, n = labels.GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) v[i] = l[i] ? 100.0f : 30.0f;
  return image;
}

ImageGeometry preopGrid()
{
  return brainshift::testing::grid({{64, 64, 64}}, {1.5, 1.5, 1.5}, point(2.0 - 47.25, -4.0 - 47.25, 6.0 - 47.25));
}

ImageGeometry intraopGrid()
{
  // Thick slices, another orientation: the target is reached through the rigid transform only.
  return brainshift::testing::grid({{96, 96, 44}}, {1.25, 1.25, 2.5}, point(-55, -62, -50),
                                   brainshift::testing::rotationAbout(0.2, 1.0, 0.3, 12.0));
}

/// The sphere's mesh at 3 mm (or `resolutionMm`) of the labels `meshed`.
MeshingParameters sphereMeshing(std::vector<int> meshed = {2}, double resolutionMm = 3.0)
{
  MeshingParameters meshing;
  meshing.resolutionMm = resolutionMm;
  meshing.labels = std::move(meshed);
  return meshing;
}

void sphereShrinks()
{
  const auto preop = sphereLabels(preopGrid(), 35.0, nullptr, false, false);
  const MeshingParameters meshing = sphereMeshing();
  const LabelMapMesh mesh = meshLabelMap(*preop, meshing);
  const auto rigid = brainshift::testing::makeRigidTransform(); // intraop -> preop
  const auto intraop = sphereLabels(intraopGrid(), 32.0, rigid.GetPointer(), false, false);
  const auto image = intensityOf(*intraop);
  ActiveSurfaceParameters parameters;
  const ActiveSurfaceResult result = deformBrainSurface(mesh.mesh, preop.GetPointer(), *intraop, image.GetPointer(), *rigid, parameters);
  std::cout << "sphere: " << result.surfaceNodes << " nodes, " << result.iterations << " iterations, residual "
            << result.initialMeanResidualMm << " -> " << result.meanResidualMm << " mm, image term at " << result.imageTermNodes
            << " nodes, expected grey levels " << result.expectedInsideIntensity << " / " << result.expectedOutsideIntensity << "\n";
  {
    ActiveSurfaceParameters segmentationOnly;
    segmentationOnly.imageWeight = 0;
    const ActiveSurfaceResult plain = deformBrainSurface(mesh.mesh, preop.GetPointer(), *intraop, nullptr, *rigid, segmentationOnly);
    std::cout << "  segmentation only: " << plain.iterations << " iterations, residual " << plain.meanResidualMm << " mm\n";
  }
  BS_CHECK(result.converged);
  BS_CHECK(result.imposedNodes == result.surfaceNodes);
  BS_CHECK(result.flippedTriangles == 0);
  BS_CHECK(result.initialMeanResidualMm > 2.0);
  BS_CHECK_MSG(result.meanResidualMm < 0.3, result.meanResidualMm);
  BS_CHECK(result.imageTermNodes == 0); // the segmentation shows the expected contrast everywhere
  BS_CHECK_NEAR(result.expectedInsideIntensity, 100.0, 1.0);
  BS_CHECK_NEAR(result.expectedOutsideIntensity, 30.0, 1.0);
  // Each node moves 3 mm towards the centre (the mesh's nodes are only near the preoperative
  // boundary; they move as the boundary does, wherever they sit on the staircase).
  vtkPolyData* s = result.surface;
  vtkDataArray* displacement = s->GetPointData()->GetArray("Displacement");
  BS_CHECK(s->GetPointData()->GetArray("DisplacementMagnitude") && s->GetPointData()->GetArray("MeshNodeId") &&
           s->GetPointData()->GetArray("Imposed"));
  double radiusError = 0, tangential = 0, radial = 0;
  (void)sphereCentre;
  for (vtkIdType i = 0; i < s->GetNumberOfPoints(); ++i) {
    double x[3], u[3];
    s->GetPoint(i, x);
    displacement->GetTuple(i, u);
    double n[3], r = 0, along = 0;
    for (int k = 0; k < 3; ++k) {
      n[k] = x[k] - u[k] - sphereCentre[unsigned(k)];
      r += n[k] * n[k];
    }
    r = std::sqrt(r);
    for (int k = 0; k < 3; ++k) {
      n[k] /= r;
      along += u[k] * n[k];
    }
    radiusError += std::abs(along + 3.0); // each node moves as the boundary near it: 3 mm in
    radial += along;
    double t2 = 0;
    for (int k = 0; k < 3; ++k) t2 += (u[k] - along * n[k]) * (u[k] - along * n[k]);
    tangential += std::sqrt(t2);
  }
  const double count = double(s->GetNumberOfPoints());
  std::cout << "  |radial move + 3| " << radiusError / count << " mm, radial move " << radial / count << " mm, tangential "
            << tangential / count << " mm\n";
  BS_CHECK_MSG(radiusError / count < 0.3, radiusError / count);
  BS_CHECK_NEAR(radial / count, -3.0, 0.2);
  BS_CHECK_MSG(tangential / count < 0.4, tangential / count);

  // Deterministic.
  const ActiveSurfaceResult again = deformBrainSurface(mesh.mesh, preop.GetPointer(), *intraop, image.GetPointer(), *rigid, parameters);
  vtkDataArray* other = again.surface->GetPointData()->GetArray("Displacement");
  for (vtkIdType i = 0; i < s->GetNumberOfPoints(); ++i) {
    for (int k = 0; k < 3; ++k) BS_CHECK(displacement->GetComponent(i, k) == other->GetComponent(i, k));
  }

  // A later scan reuses the preoperative fit found by this one (PreopBoundary): the same answer,
  // without fitting the preoperative labels again.
  BS_CHECK(s->GetPointData()->GetArray("PreopBoundary") != nullptr);
  const ActiveSurfaceResult reused =
    deformBrainSurface(mesh.mesh, preop.GetPointer(), *intraop, image.GetPointer(), *rigid, parameters, {}, s);
  vtkDataArray* reusedDisplacement = reused.surface->GetPointData()->GetArray("Displacement");
  double largest = 0;
  for (vtkIdType i = 0; i < s->GetNumberOfPoints(); ++i) {
    for (int k = 0; k < 3; ++k) largest = std::max(largest, std::abs(displacement->GetComponent(i, k) - reusedDisplacement->GetComponent(i, k)));
  }
  BS_CHECK_MSG(largest < 1e-9, largest);
  // A surface of another mesh is refused, by name.
  MeshingParameters coarser = meshing;
  coarser.resolutionMm = 4.0;
  const LabelMapMesh otherMesh = meshLabelMap(*preop, coarser);
  ActiveSurfaceInputNames names;
  names.previousSurface = "scan-1/brain_surface.vtp";
  BS_CHECK_THROWS(deformBrainSurface(otherMesh.mesh, preop.GetPointer(), *intraop, image.GetPointer(), *rigid, parameters, names, s),
                  InputError, "scan-1/brain_surface.vtp");

  // Segmentation alone (no image term) also lands.
  ActiveSurfaceParameters segmentationOnly;
  segmentationOnly.imageWeight = 0;
  const ActiveSurfaceResult plain = deformBrainSurface(mesh.mesh, preop.GetPointer(), *intraop, nullptr, *rigid, segmentationOnly);
  BS_CHECK(plain.imageTermNodes == 0);
  BS_CHECK_MSG(plain.meanResidualMm < 0.3, plain.meanResidualMm);
}

void imageGuardsAgainstAWrongSegmentation()
{
  // The intraoperative segmentation is eroded by 4 mm over a cap of the sphere (a classification
  // that took brain for fluid there); the image still shows the whole sphere.
  const auto preop = sphereLabels(preopGrid(), 35.0, nullptr, false, false);
  const MeshingParameters meshing = sphereMeshing();
  const LabelMapMesh mesh = meshLabelMap(*preop, meshing);
  auto identity = itk::Euler3DTransform<double>::New();
  const auto truth = sphereLabels(intraopGrid(), 32.0, nullptr, false, false);
  const auto image = intensityOf(*truth);
  auto eroded = sphereLabels(intraopGrid(), 32.0, nullptr, false, false);
  itk::ImageRegionIteratorWithIndex<LabelImage> it(eroded, eroded->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint y;
    eroded->TransformIndexToPhysicalPoint(it.GetIndex(), y);
    if (y[2] - sphereCentre[2] > 20.0 && y.EuclideanDistanceTo(sphereCentre) > 28.0) it.Set(0);
  }
  auto capError = [&](const ActiveSurfaceResult& r) { // mean |radial move + 3| over the cap
    vtkDataArray* u = r.surface->GetPointData()->GetArray("Displacement");
    double sum = 0;
    int count = 0;
    for (vtkIdType i = 0; i < r.surface->GetNumberOfPoints(); ++i) {
      double x[3], d[3], radial = 0, length = 0;
      r.surface->GetPoint(i, x);
      u->GetTuple(i, d);
      for (int k = 0; k < 3; ++k) length += (x[k] - d[k] - sphereCentre[unsigned(k)]) * (x[k] - d[k] - sphereCentre[unsigned(k)]);
      length = std::sqrt(length);
      for (int k = 0; k < 3; ++k) radial += d[k] * (x[k] - d[k] - sphereCentre[unsigned(k)]) / length;
      if (x[2] - d[2] - sphereCentre[2] < 26.0) continue;
      sum += std::abs(radial + 3.0);
      ++count;
    }
    return sum / std::max(count, 1);
  };
  ActiveSurfaceParameters segmentationOnly;
  segmentationOnly.imageRescue = false;
  const ActiveSurfaceResult followed = deformBrainSurface(mesh.mesh, preop.GetPointer(), *eroded, image.GetPointer(), *identity, segmentationOnly);
  const ActiveSurfaceResult guarded = deformBrainSurface(mesh.mesh, preop.GetPointer(), *eroded, image.GetPointer(), *identity, ActiveSurfaceParameters{});
  std::cout << "eroded cap: error " << capError(followed) << " mm following the segmentation, " << capError(guarded)
            << " mm guarded by the image (" << guarded.imageTermNodes << " nodes on the image's edge)\n";
  BS_CHECK(capError(followed) > 2.0);
  BS_CHECK_MSG(capError(guarded) < 1.2 && capError(guarded) < 0.4 * capError(followed), capError(guarded));
  BS_CHECK(guarded.imageTermNodes > 50);
}

void resectedTumourIsFree()
{
  const auto preop = sphereLabels(preopGrid(), 35.0, nullptr, true, false);
  const MeshingParameters meshing = sphereMeshing({2, 4});
  const LabelMapMesh mesh = meshLabelMap(*preop, meshing);
  auto identity = itk::Euler3DTransform<double>::New();
  const auto intraop = sphereLabels(preopGrid(), 35.0, nullptr, true, true); // the cavity opens at the top
  const ActiveSurfaceResult result = deformBrainSurface(mesh.mesh, preop.GetPointer(), *intraop, nullptr, *identity, ActiveSurfaceParameters{});
  std::cout << "resected: " << result.freeResected << " free of " << result.surfaceNodes << ", residual " << result.meanResidualMm
            << " mm\n";
  BS_CHECK(result.tumourResected);
  BS_CHECK(result.freeResected > 10);
  BS_CHECK(result.imposedNodes + result.freeResected + result.freeUnmatched == result.surfaceNodes);
  BS_CHECK_MSG(result.meanResidualMm < 0.5, result.meanResidualMm);
  // The free nodes are the tumour's: high on the sphere.
  vtkDataArray* imposed = result.surface->GetPointData()->GetArray("Imposed");
  for (vtkIdType i = 0; i < result.surface->GetNumberOfPoints(); ++i) {
    if (imposed->GetComponent(i, 0) > 0.5) continue;
    double x[3];
    result.surface->GetPoint(i, x);
    BS_CHECK_MSG(x[2] - sphereCentre[2] > 15.0, x[2] - sphereCentre[2]);
  }
  // The tumour still there: nothing is free.
  const auto kept = sphereLabels(preopGrid(), 35.0, nullptr, true, false);
  const ActiveSurfaceResult intact = deformBrainSurface(mesh.mesh, preop.GetPointer(), *kept, nullptr, *identity, ActiveSurfaceParameters{});
  BS_CHECK(!intact.tumourResected);
  BS_CHECK(intact.imposedNodes == intact.surfaceNodes);
}

/// The largest distance between each surface point's rest position (point minus displacement)
/// and its mesh node (MeshNodeId) in `mesh`.
double restOffFromMesh(vtkPolyData* surface, vtkUnstructuredGrid* mesh)
{
  vtkDataArray* displacement = surface->GetPointData()->GetArray("Displacement");
  vtkDataArray* node = surface->GetPointData()->GetArray("MeshNodeId");
  double largest = 0;
  for (vtkIdType i = 0; i < surface->GetNumberOfPoints(); ++i) {
    double x[3], u[3], m[3];
    surface->GetPoint(i, x);
    displacement->GetTuple(i, u);
    mesh->GetPoint(vtkIdType(std::lround(node->GetComponent(i, 0))), m);
    for (int k = 0; k < 3; ++k) largest = std::max(largest, std::abs(x[k] - u[k] - m[k]));
  }
  return largest;
}

/// The surface membrane is built once for a mesh and kept for the next fit on it (a watch
/// session's scans): the same answer again, and a mesh of the same topology whose nodes moved 2 mm,
/// or whose tumour became parenchyma, gets its own membrane, not the kept one.
void membraneFollowsTheMesh()
{
  const auto preop = sphereLabels(preopGrid(), 35.0, nullptr, true, false);
  const LabelMapMesh mesh = meshLabelMap(*preop, sphereMeshing({2, 4}));
  auto identity = itk::Euler3DTransform<double>::New();
  const auto resected = sphereLabels(preopGrid(), 35.0, nullptr, true, true);
  const ActiveSurfaceResult first = deformBrainSurface(mesh.mesh, preop.GetPointer(), *resected, nullptr, *identity, ActiveSurfaceParameters{});
  BS_CHECK(first.tumourResected && first.freeResected > 10);
  BS_CHECK_MSG(restOffFromMesh(first.surface, mesh.mesh) < 1e-9, restOffFromMesh(first.surface, mesh.mesh));

  vtkNew<vtkUnstructuredGrid> moved;
  moved->DeepCopy(mesh.mesh);
  for (vtkIdType i = 0; i < moved->GetNumberOfPoints(); ++i) {
    double x[3];
    moved->GetPoint(i, x);
    x[0] += 2.0;
    moved->GetPoints()->SetPoint(i, x);
  }
  const ActiveSurfaceResult onMoved = deformBrainSurface(moved, preop.GetPointer(), *resected, nullptr, *identity, ActiveSurfaceParameters{});
  std::cout << "membrane: rest positions " << restOffFromMesh(onMoved.surface, moved) << " mm off the moved mesh's nodes\n";
  BS_CHECK_MSG(restOffFromMesh(onMoved.surface, moved) < 1e-9, restOffFromMesh(onMoved.surface, moved));

  vtkNew<vtkUnstructuredGrid> noTumour;
  noTumour->DeepCopy(mesh.mesh);
  vtkDataArray* labels = noTumour->GetCellData()->GetArray("Label");
  for (vtkIdType c = 0; c < labels->GetNumberOfTuples(); ++c) {
    if (std::lround(labels->GetComponent(c, 0)) == 4) labels->SetComponent(c, 0, 2);
  }
  const ActiveSurfaceResult withoutTumour =
    deformBrainSurface(noTumour, preop.GetPointer(), *resected, nullptr, *identity, ActiveSurfaceParameters{});
  BS_CHECK_MSG(!withoutTumour.tumourResected && withoutTumour.freeResected == 0, withoutTumour.freeResected);

  const ActiveSurfaceResult again = deformBrainSurface(mesh.mesh, preop.GetPointer(), *resected, nullptr, *identity, ActiveSurfaceParameters{});
  vtkDataArray* u0 = first.surface->GetPointData()->GetArray("Displacement");
  vtkDataArray* u1 = again.surface->GetPointData()->GetArray("Displacement");
  BS_CHECK(again.surface->GetNumberOfPoints() == first.surface->GetNumberOfPoints() && again.freeResected == first.freeResected);
  for (vtkIdType i = 0; i < first.surface->GetNumberOfPoints(); ++i) {
    for (int k = 0; k < 3; ++k) BS_CHECK(u0->GetComponent(i, k) == u1->GetComponent(i, k));
  }
}

/// A deep, narrow sink (12 mm at the top of a 35 mm sphere, a Gaussian of 12 mm): the membrane's
/// equilibrium leaves the bottom of the bowl short of the target (the filter's loss grows with the
/// motion's curvature); the residual correction (twicing) takes most of it up, ends nearer the
/// target on average, and folds nothing. Its default is the configuration's.
void deepSinkReachesItsBottom()
{
  const auto preop = sphereLabels(preopGrid(), 35.0, nullptr, false, false);
  const MeshingParameters meshing = sphereMeshing();
  const LabelMapMesh mesh = meshLabelMap(*preop, meshing);
  auto identity = itk::Euler3DTransform<double>::New();
  const double depth = 12.0, sigma = 12.0;
  auto sunkenRadius = [&](double offAxis) { return 35.0 - depth * std::exp(-offAxis * offAxis / (2 * sigma * sigma)); };
  auto sunken = brainshift::testing::makeImage<LabelImage>(preopGrid());
  itk::ImageRegionIteratorWithIndex<LabelImage> it(sunken, sunken->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint x;
    sunken->TransformIndexToPhysicalPoint(it.GetIndex(), x);
    const double offAxis = std::hypot(x[0] - sphereCentre[0], x[1] - sphereCentre[1]);
    const double radius = sunkenRadius(offAxis); // the upper half's surface: the sphere pushed down along the axis
    const double top = sphereCentre[2] + std::sqrt(std::max(0.0, radius * radius - offAxis * offAxis));
    it.Set(x.EuclideanDistanceTo(sphereCentre) <= 35.0 && (x[2] <= sphereCentre[2] || x[2] <= top) ? 2 : 0);
  }
  // Over the bowl's bottom (within 4 mm of the axis): how far above the sunken surface the nodes end (mm).
  auto shortOfBottom = [&](const ActiveSurfaceResult& r) {
    double sum = 0;
    int count = 0;
    for (vtkIdType i = 0; i < r.surface->GetNumberOfPoints(); ++i) {
      double x[3];
      r.surface->GetPoint(i, x);
      const double offAxis = std::hypot(x[0] - sphereCentre[0], x[1] - sphereCentre[1]);
      if (offAxis > 4.0 || x[2] < sphereCentre[2]) continue;
      const double radius = sunkenRadius(offAxis);
      sum += x[2] - (sphereCentre[2] + std::sqrt(radius * radius - offAxis * offAxis));
      ++count;
    }
    BS_CHECK(count >= 3);
    return sum / std::max(count, 1);
  };
  ActiveSurfaceParameters membraneAlone;
  membraneAlone.residualCorrection = false;
  const ActiveSurfaceResult plain = deformBrainSurface(mesh.mesh, preop.GetPointer(), *sunken, nullptr, *identity, membraneAlone);
  const ActiveSurfaceResult corrected = deformBrainSurface(mesh.mesh, preop.GetPointer(), *sunken, nullptr, *identity, ActiveSurfaceParameters{});
  std::cout << "deep sink: the bowl's bottom " << shortOfBottom(plain) << " mm short with the membrane alone, " << shortOfBottom(corrected)
            << " mm with the residual corrected (correction " << corrected.residualCorrectionMeanMm << " mm mean, "
            << corrected.residualCorrectionMaxMm << " max); residual " << plain.meanResidualMm << " -> " << corrected.meanResidualMm << " mm\n";
  BS_CHECK(plain.residualCorrectionMaxMm == 0);
  BS_CHECK(activeSurfaceParametersFrom(Configuration{}).residualCorrection == ActiveSurfaceParameters{}.residualCorrection);
  BS_CHECK_MSG(shortOfBottom(plain) > 0.5, shortOfBottom(plain));
  BS_CHECK_MSG(std::abs(shortOfBottom(corrected)) < 0.5 * shortOfBottom(plain), shortOfBottom(corrected));
  BS_CHECK_MSG(corrected.meanResidualMm < plain.meanResidualMm, corrected.meanResidualMm);
  BS_CHECK(corrected.flippedTriangles == 0 && corrected.residualCorrectionMaxMm > 0.3);
}

/// The segmentation's own offset: the intraoperative brain is the preoperative sphere (35 mm)
/// with a sink of 6 mm at the top (a Gaussian of 10 mm); its segmentation puts the whole boundary
/// `bias` mm inside (a contrast that shows the edge elsewhere). Returns the mean radial
/// move of the nodes far from the sink (more than 30 mm off its axis, or below the equator) and of
/// those at its bottom (within 4 mm of the axis).
struct OffsetCase {
  ActiveSurfaceResult result;
  double farMoveMm = 0, sinkMoveMm = 0;
};
OffsetCase sinkSeenWithOffset(double bias, const ActiveSurfaceParameters& parameters)
{
  const auto preop = sphereLabels(preopGrid(), 35.0, nullptr, false, false);
  const LabelMapMesh mesh = meshLabelMap(*preop, sphereMeshing());
  auto identity = itk::Euler3DTransform<double>::New();
  auto sinkAt = [](const PhysicalPoint& x) {
    const double offAxis = std::hypot(x[0] - sphereCentre[0], x[1] - sphereCentre[1]);
    return x[2] > sphereCentre[2] ? 6.0 * std::exp(-offAxis * offAxis / (2 * 10.0 * 10.0)) : 0.0;
  };
  auto segmented = brainshift::testing::makeImage<LabelImage>(preopGrid());
  itk::ImageRegionIteratorWithIndex<LabelImage> it(segmented, segmented->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint x;
    segmented->TransformIndexToPhysicalPoint(it.GetIndex(), x);
    it.Set(x.EuclideanDistanceTo(sphereCentre) <= 35.0 - sinkAt(x) - bias ? 2 : 0);
  }
  OffsetCase c;
  c.result = deformBrainSurface(mesh.mesh, preop.GetPointer(), *segmented, nullptr, *identity, parameters);
  vtkDataArray* u = c.result.surface->GetPointData()->GetArray("Displacement");
  double far = 0, sink = 0;
  int farCount = 0, sinkCount = 0;
  for (vtkIdType i = 0; i < c.result.surface->GetNumberOfPoints(); ++i) {
    double moved[3], d[3];
    c.result.surface->GetPoint(i, moved);
    u->GetTuple(i, d);
    const PhysicalPoint before = point(moved[0] - d[0], moved[1] - d[1], moved[2] - d[2]);
    const double r = before.EuclideanDistanceTo(sphereCentre);
    double move = 0; // along the outward radius
    for (int a = 0; a < 3; ++a) move += d[a] * (before[a] - sphereCentre[a]) / r;
    const double offAxis = std::hypot(before[0] - sphereCentre[0], before[1] - sphereCentre[1]);
    if (offAxis > 30.0 || before[2] < sphereCentre[2]) {
      far += move;
      ++farCount;
    } else if (offAxis < 4.0) {
      sink += move;
      ++sinkCount;
    }
  }
  BS_CHECK(farCount > 100 && sinkCount >= 3);
  c.farMoveMm = far / farCount;
  c.sinkMoveMm = sink / sinkCount;
  return c;
}

/// A segmentation that puts the whole boundary 1 mm inside: the offset is measured (the median
/// normal move, within 0.3 mm) and a warning says the update carries it into the brain (the rest
/// band off: a 1 mm band would hold nearly all of it, restBandHoldsTheStillSurface); the same
/// sink segmented without an offset measures none (within 0.3 mm) and warns of nothing.
void segmentationOffsetIsReported()
{
  ActiveSurfaceParameters unbanded; // what the surface carries, before the rest band holds any of it
  unbanded.restBandMm = 0;
  const OffsetCase offset = sinkSeenWithOffset(1.0, unbanded);
  const OffsetCase none = sinkSeenWithOffset(0.0, unbanded);
  std::cout << "segmentation offset 1 mm: measured " << offset.result.boundaryOffsetMm << " mm over " << offset.result.boundaryOffsetNodes
            << " nodes (far from the sink the surface moved " << offset.farMoveMm << " mm); none: " << none.result.boundaryOffsetMm
            << " mm (" << none.farMoveMm << " mm)\n";
  auto warnsOfOffset = [](const ActiveSurfaceResult& r) {
    for (const std::string& w : r.warnings) {
      if (w.find("intraoperative brain boundary lies") != std::string::npos) return true;
    }
    return false;
  };
  BS_CHECK_NEAR(offset.result.boundaryOffsetMm, -1.0, 0.3);
  BS_CHECK(offset.result.boundaryOffsetNodes > offset.result.surfaceNodes / 2);
  BS_CHECK_NEAR(offset.farMoveMm, -1.0, 0.3); // measured, not taken off
  BS_CHECK(warnsOfOffset(offset.result));
  BS_CHECK(none.result.boundaryOffsetNodes > none.result.surfaceNodes / 2); // measured, and found none
  BS_CHECK_NEAR(none.result.boundaryOffsetMm, 0.0, 0.3);
  BS_CHECK(!warnsOfOffset(none.result));
}

/// The rest band: the same sink segmented 0.6 mm inside everywhere. Without the band the surface
/// far from the sink carries the segmentation's offset (about -0.6 mm); with a band of 1 mm it is
/// held at rest there (less than a fifth of it left: nodes the membrane also moved sideways are
/// only scaled down), while the sink's bottom (6 mm, beyond twice the band) moves
/// exactly as without it; the nodes held and scaled are counted, nothing folds, and the
/// configuration's default is the parameters'. Judged on each node's own move (no smoothing), every
/// imposed displacement is the ramp's exactly. A band out of range is refused.
void restBandHoldsTheStillSurface()
{
  ActiveSurfaceParameters off, banded;
  off.restBandMm = 0;
  banded.restBandMm = 1.0;
  banded.restBandSmoothingPasses = 4;
  const OffsetCase plain = sinkSeenWithOffset(0.6, off);
  const OffsetCase held = sinkSeenWithOffset(0.6, banded);
  std::cout << "rest band 1 mm: far from the sink " << plain.farMoveMm << " -> " << held.farMoveMm << " mm, sink's bottom "
            << plain.sinkMoveMm << " -> " << held.sinkMoveMm << " mm; " << held.result.restHeldNodes << " nodes held, "
            << held.result.restScaledNodes << " scaled of " << held.result.imposedNodes << " imposed, median local move "
            << held.result.restLocalMoveMedianMm << " mm\n";
  BS_CHECK_NEAR(plain.farMoveMm, -0.6, 0.25);
  BS_CHECK_MSG(std::abs(held.farMoveMm) < 0.2 * std::abs(plain.farMoveMm), held.farMoveMm);
  BS_CHECK_MSG(plain.sinkMoveMm < -5.0, plain.sinkMoveMm);
  BS_CHECK_NEAR(held.sinkMoveMm, plain.sinkMoveMm, 1e-9);
  BS_CHECK(plain.result.restLocalMoveMedianMm == 0); // band off: nothing judged
  // Over a surface most of which did not move: the offset and what the membrane moved sideways.
  BS_CHECK_MSG(held.result.restLocalMoveMedianMm > 0.5 && held.result.restLocalMoveMedianMm < 1.2, held.result.restLocalMoveMedianMm);
  // The ramp itself, on each node's own move (no smoothing): every imposed node's displacement is
  // the unbanded one times clamp((|u| - 1) / 1, 0, 1), and the counts are those nodes.
  ActiveSurfaceParameters ownMove = banded;
  ownMove.restBandSmoothingPasses = 0;
  const OffsetCase own = sinkSeenWithOffset(0.6, ownMove);
  vtkDataArray* before = plain.result.surface->GetPointData()->GetArray("Displacement");
  vtkDataArray* after = own.result.surface->GetPointData()->GetArray("Displacement");
  vtkDataArray* imposed = own.result.surface->GetPointData()->GetArray("Imposed");
  std::size_t expectHeld = 0, expectScaled = 0;
  double largestDeparture = 0;
  for (vtkIdType i = 0; i < own.result.surface->GetNumberOfPoints(); ++i) {
    if (imposed->GetTuple1(i) == 0) continue;
    double u[3], v[3];
    before->GetTuple(i, u);
    after->GetTuple(i, v);
    const double scale = std::clamp((std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]) - 1.0) / 1.0, 0.0, 1.0);
    expectHeld += scale == 0;
    expectScaled += scale > 0 && scale < 1;
    for (int a = 0; a < 3; ++a) largestDeparture = std::max(largestDeparture, std::abs(v[a] - scale * u[a]));
  }
  std::cout << "  each node's own move: " << own.result.restHeldNodes << " held, " << own.result.restScaledNodes
            << " scaled; largest departure from the ramp " << largestDeparture << " mm\n";
  BS_CHECK_MSG(largestDeparture < 1e-9, largestDeparture);
  BS_CHECK(own.result.restHeldNodes == expectHeld && own.result.restScaledNodes == expectScaled && expectScaled > 0);
  // The local mean averages the boundary's node-to-node noise down: more of the still surface held whole.
  BS_CHECK(held.result.restHeldNodes > own.result.restHeldNodes && std::abs(held.farMoveMm) < std::abs(own.farMoveMm));
  BS_CHECK(held.result.restHeldNodes > held.result.imposedNodes / 4 && held.result.restScaledNodes > 0);
  BS_CHECK(held.result.restHeldNodes + held.result.restScaledNodes > held.result.imposedNodes / 2);
  BS_CHECK(held.result.restHeldNodes + held.result.restScaledNodes < held.result.imposedNodes);
  BS_CHECK(held.result.flippedTriangles == 0 && held.result.imposedNodes == plain.result.imposedNodes);
  BS_CHECK(activeSurfaceParametersFrom(Configuration{}).restBandMm == ActiveSurfaceParameters{}.restBandMm);
  BS_CHECK(activeSurfaceParametersFrom(Configuration{}).restBandSmoothingPasses == ActiveSurfaceParameters{}.restBandSmoothingPasses);
  ActiveSurfaceParameters absurd;
  absurd.restBandMm = -1.0;
  BS_CHECK_THROWS(absurd.validate(), InputError, "rest band");
  absurd.restBandMm = std::nan("");
  BS_CHECK_THROWS(absurd.validate(), InputError, "rest band");
  absurd.restBandMm = 1.0;
  absurd.restBandSmoothingPasses = 1000;
  BS_CHECK_THROWS(absurd.validate(), InputError, "smoothing passes");
}

/// An axial slab through the sphere's middle (`slices` of 2.5 mm) as the intraoperative grid.
ImageGeometry slabGrid(std::size_t slices)
{
  const double halfThickness = 0.5 * 2.5 * double(slices - 1);
  return brainshift::testing::grid({{96, 96, slices}}, {1.25, 1.25, 2.5}, point(-55, -62, sphereCentre[2] - halfThickness));
}

/// A partial field of view: a slab 27.5 mm thick through a sphere of 35 mm that shrinks by 3 mm.
/// The nodes it covers move onto the target; the others are held at rest (imposed, zero
/// displacement) or, when asked, left free; a slab of two slices covers too little to say anything.
void slabFieldOfView()
{
  const auto preop = sphereLabels(preopGrid(), 35.0, nullptr, false, false);
  const MeshingParameters meshing = sphereMeshing();
  const LabelMapMesh mesh = meshLabelMap(*preop, meshing);
  auto identity = itk::Euler3DTransform<double>::New();
  const auto slab = sphereLabels(slabGrid(12), 32.0, nullptr, false, false);
  const ActiveSurfaceResult held = deformBrainSurface(mesh.mesh, preop.GetPointer(), *slab, intensityOf(*slab).GetPointer(), *identity,
                                                      ActiveSurfaceParameters{});
  const double share = double(held.coveredSurfaceNodes) / double(held.surfaceNodes);
  std::cout << "slab: " << held.coveredSurfaceNodes << " of " << held.surfaceNodes << " nodes inside (" << share << "), "
            << held.coveredBrainMl << " of " << held.meshedBrainMl << " ml, residual " << held.meanResidualMm << " mm\n";
  BS_CHECK_MSG(share > 0.3 && share < 0.5, share); // a sphere's zone of height h holds h / 2R of its area: 0.39
  BS_CHECK(held.heldOutsideImage + held.coveredSurfaceNodes == held.surfaceNodes && held.freeOutsideImage == 0);
  BS_CHECK(held.boundaryOffsetNodes == 0); // 39 % of the surface in view: the offset is not measured
  BS_CHECK_MSG(held.coveredBrainMl > 0.3 * held.meshedBrainMl && held.coveredBrainMl < 0.7 * held.meshedBrainMl, held.coveredBrainMl);
  BS_CHECK_MSG(held.meanResidualMm < 0.5, held.meanResidualMm);
  vtkPolyData* s = held.surface;
  vtkDataArray* displacement = s->GetPointData()->GetArray("Displacement");
  vtkDataArray* imposed = s->GetPointData()->GetArray("Imposed");
  double inwardSum = 0;
  std::size_t inwardCount = 0, heldMoving = 0, heldFree = 0;
  for (vtkIdType i = 0; i < s->GetNumberOfPoints(); ++i) {
    double x[3], u[3];
    s->GetPoint(i, x);
    displacement->GetTuple(i, u);
    const double z = x[2] - u[2] - sphereCentre[2], length = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    if (std::abs(z) > 16.0) { // beyond the slab's faces (13.75 mm) and the mesh's step
      heldMoving += length > 0;
      heldFree += imposed->GetComponent(i, 0) < 0.5;
    } else if (std::abs(z) < 8.0) {
      inwardSum += length;
      ++inwardCount;
    }
  }
  BS_CHECK(heldMoving == 0 && heldFree == 0);
  BS_CHECK_MSG(inwardCount > 100 && std::abs(inwardSum / double(inwardCount) - 3.0) < 0.6, inwardSum / double(inwardCount));
  // Left free instead: the same nodes, Imposed 0.
  ActiveSurfaceParameters free;
  free.holdOutsideFieldOfView = false;
  const ActiveSurfaceResult freed = deformBrainSurface(mesh.mesh, preop.GetPointer(), *slab, nullptr, *identity, free);
  BS_CHECK(freed.freeOutsideImage == held.heldOutsideImage && freed.heldOutsideImage == 0);
  BS_CHECK(freed.imposedNodes + freed.freeOutsideImage + freed.freeUnmatched == freed.surfaceNodes);
  // Two slices: about 7 % of the surface; refused with the figures.
  const auto thin = sphereLabels(slabGrid(2), 32.0, nullptr, false, false);
  BS_CHECK_THROWS(deformBrainSurface(mesh.mesh, preop.GetPointer(), *thin, nullptr, *identity, ActiveSurfaceParameters{}), InputError,
                  "covers too little of the brain to match its surface");
  try {
    deformBrainSurface(mesh.mesh, preop.GetPointer(), *thin, nullptr, *identity, ActiveSurfaceParameters{});
  } catch (const InputError& e) {
    std::cout << "thin slab: " << e.what() << "\n";
    BS_CHECK_MSG(std::string(e.what()).find("% of the brain surface nodes") != std::string::npos, e.what());
  }
}

void smallCaseAgainstTruth()
{
  CaseParameters parameters;
  parameters.size = CaseSize::Small;
  const SimulatedCase c = simulateCase(parameters);
  MeshingParameters meshing;
  meshing.resolutionMm = 4.0;
  const LabelMapMesh mesh = meshLabelMap(*c.preopLabels, meshing);
  const ActiveSurfaceResult result =
    deformBrainSurface(mesh.mesh, c.preopLabels.GetPointer(), *c.intraopLabels, c.intraopImage.GetPointer(), *c.rigidIntraopToPreop, ActiveSurfaceParameters{});
  const SurfaceDisplacementAccuracy a =
    evaluateSurfaceDisplacement(result.surface, *c.intraopToPreop, *c.rigidIntraopToPreop, *c.preopLabels);
  std::cout << "small case: " << result.surfaceNodes << " nodes, " << result.imposedNodes << " imposed, " << result.iterations
            << " iterations, residual " << result.initialMeanResidualMm << " -> " << result.meanResidualMm << " mm\n"
            << "  error mean " << a.meanErrorMm << " p95 " << a.p95ErrorMm << " max " << a.maxErrorMm << " mm (true mean "
            << a.meanTrueDisplacementMm << ", max " << a.maxTrueDisplacementMm << "); moving " << a.movingNodes << " nodes: error "
            << a.movingMeanErrorMm << " mm of " << a.movingMeanTrueDisplacementMm << " mm; residual to the true boundary "
            << a.meanResidualMm << " mm\n";
  BS_CHECK(result.converged);
  BS_CHECK_MSG(result.flippedTriangles <= std::size_t(result.surface->GetNumberOfCells() / 1000), result.flippedTriangles);
  BS_CHECK(a.maxTrueDisplacementMm > 7.0);
  BS_CHECK(a.movingNodes > 20);
  // Where the brain sank, the surface follows it: the error is a fraction of the shift.
  BS_CHECK_MSG(a.movingMeanErrorMm < 0.3 * a.movingMeanTrueDisplacementMm, a.movingMeanErrorMm);
  BS_CHECK_MSG(a.meanErrorMm < 1.0, a.meanErrorMm);
  BS_CHECK_MSG(a.meanResidualMm < 1.0, a.meanResidualMm);
}

void badInput()
{
  const auto preop = sphereLabels(preopGrid(), 35.0, nullptr, false, false);
  const MeshingParameters meshing = sphereMeshing({2}, 4.0);
  const LabelMapMesh mesh = meshLabelMap(*preop, meshing);
  auto identity = itk::Euler3DTransform<double>::New();
  const ActiveSurfaceParameters parameters;
  ActiveSurfaceInputNames names;
  names.labels = "intraop_labels.nii.gz";
  names.mesh = "mesh.vtu";

  auto empty = brainshift::testing::makeImage<LabelImage>(preopGrid());
  empty->FillBuffer(0);
  BS_CHECK_THROWS(deformBrainSurface(mesh.mesh, preop.GetPointer(), *empty, nullptr, *identity, parameters, names), InputError,
                  "intraop_labels.nii.gz: the intraoperative segmentation holds no brain");

  // Two equal brains apart.
  auto disjoint = brainshift::testing::makeImage<LabelImage>(preopGrid());
  itk::ImageRegionIteratorWithIndex<LabelImage> it(disjoint, disjoint->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) it.Set((it.GetIndex()[0] - 16) * (it.GetIndex()[0] - 16) + (it.GetIndex()[1] - 32) * (it.GetIndex()[1] - 32) +
                                           (it.GetIndex()[2] - 32) * (it.GetIndex()[2] - 32) < 100 ||
                                         (it.GetIndex()[0] - 48) * (it.GetIndex()[0] - 48) + (it.GetIndex()[1] - 32) * (it.GetIndex()[1] - 32) +
                                           (it.GetIndex()[2] - 32) * (it.GetIndex()[2] - 32) < 100 ? 2 : 0);
  BS_CHECK_THROWS(deformBrainSurface(mesh.mesh, preop.GetPointer(), *disjoint, nullptr, *identity, parameters, names), InputError, "disjoint");

  // Cancelled (the host's Cancel): CancelledError, no surface.
  {
    std::atomic<bool> cancel{true};
    ActiveSurfaceParameters cancelled = parameters;
    cancelled.cancel = &cancel;
    auto brain = brainshift::testing::makeImage<LabelImage>(preopGrid());
    itk::ImageRegionIteratorWithIndex<LabelImage> b(brain, brain->GetLargestPossibleRegion());
    for (; !b.IsAtEnd(); ++b) {
      const auto i = b.GetIndex();
      b.Set((i[0] - 32) * (i[0] - 32) + (i[1] - 32) * (i[1] - 32) + (i[2] - 32) * (i[2] - 32) < 400 ? 2 : 0);
    }
    BS_CHECK_THROWS(deformBrainSurface(mesh.mesh, preop.GetPointer(), *brain, nullptr, *identity, cancelled, names), CancelledError,
                    "the active surface cancelled");
  }

  // The surface far from the intraoperative image.
  auto far = itk::Euler3DTransform<double>::New();
  itk::Euler3DTransform<double>::OutputVectorType translation;
  translation.Fill(500.0);
  far->SetTranslation(translation);
  BS_CHECK_THROWS(deformBrainSurface(mesh.mesh, preop.GetPointer(), *preop, nullptr, *far, parameters, names), InputError,
                  "covers too little of the brain");

  // Labels and image on different grids.
  const auto otherGrid = intensityOf(*sphereLabels(intraopGrid(), 30.0, nullptr, false, false));
  BS_CHECK_THROWS(deformBrainSurface(mesh.mesh, preop.GetPointer(), *preop, otherGrid.GetPointer(), *identity, parameters, names), InputError,
                  "not on the intraoperative image's grid");

  // A mesh whose brain surface is not a manifold: two tetrahedra touching at an edge only.
  vtkNew<vtkUnstructuredGrid> edgeOnly;
  vtkNew<vtkPoints> points;
  const double coordinates[6][3] = {{0, 0, 0}, {10, 0, 0}, {0, 10, 0}, {0, 0, 10}, {10, 10, 10}, {10, 10, -10}};
  for (const auto& c : coordinates) points->InsertNextPoint(c);
  edgeOnly->SetPoints(points);
  const vtkIdType a[4] = {0, 1, 2, 3}, b[4] = {1, 2, 4, 5};
  edgeOnly->InsertNextCell(VTK_TETRA, 4, a);
  edgeOnly->InsertNextCell(VTK_TETRA, 4, b);
  vtkNew<vtkIntArray> label;
  label->SetName("Label");
  label->InsertNextValue(2);
  label->InsertNextValue(2);
  edgeOnly->GetCellData()->AddArray(label);
  BS_CHECK_THROWS(deformBrainSurface(edgeOnly, preop.GetPointer(), *preop, nullptr, *identity, parameters, names), InputError,
                  "mesh.vtu: the brain surface of the mesh is not a closed manifold");

  ActiveSurfaceParameters absurd;
  absurd.imageWeight = 2.0;
  BS_CHECK_THROWS(deformBrainSurface(mesh.mesh, preop.GetPointer(), *preop, nullptr, *identity, absurd, names), InputError, "image weight");
}
} // namespace

int ActiveSurfaceTest(int, char*[])
{
  return brainshift::testing::runTest("ActiveSurfaceTest", [] {
    sphereShrinks();
    imageGuardsAgainstAWrongSegmentation();
    resectedTumourIsFree();
    membraneFollowsTheMesh();
    deepSinkReachesItsBottom();
    segmentationOffsetIsReported();
    restBandHoldsTheStillSurface();
    slabFieldOfView();
    badInput();
    smallCaseAgainstTruth();
  });
}
