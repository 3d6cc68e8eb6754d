// The brain boundary under the craniotomy against known shifts: a ball of brain (radius 50 mm, 1 mm
// voxels) whose top sinks rigidly by 5 mm along the craniotomy axis (z) after a rigid head motion.
// Shown through the rigid motion alone, the boundary is off by the shift's normal component (5 mm
// on the axis, 3.9 mm at the 30 mm rim); through 2 mm of sinking by 3 mm's; through 7 mm it
// overshoots (negative); through the truth it is exact. The surface nodes likewise.
#include "BrainShiftTestingSupport.h"
#include "SurfaceDisplacementEvaluation.h"
#include "SyntheticData.h"

#include <itkCompositeTransform.h>
#include <itkDisplacementFieldTransform.h>
#include <itkImageRegionIteratorWithIndex.h>
#include <vtkDoubleArray.h>
#include <vtkPointData.h>
#include <vtkPoints.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <iostream>

namespace {
using namespace brainshift;
constexpr double kBall = 50.0;

/// The rigid motion followed by a sinking of `sinkMm` along z (tissue at x' came from x' + sink z).
itk::Euler3DTransform<double>::Pointer sunkBy(double sinkMm)
{
  auto t = testing::makeRigidTransform();
  auto translation = t->GetTranslation();
  translation[2] += sinkMm;
  t->SetTranslation(translation);
  return t;
}

/// The mean over the footprint's 1 mm lattice of lines of the distance from the true boundary
/// (the ball sunk by `trueSink`) to the shown one (sunk by `shownSink`), positive where the shown lies
/// outside; `count` the lines.
double expectedMean(double trueSink, double shownSink, std::size_t& count)
{
  double sum = 0;
  count = 0;
  for (int i = -30; i <= 30; ++i) {
    for (int j = -30; j <= 30; ++j) {
      const double rho2 = double(i * i + j * j);
      if (rho2 > 900) continue;
      const double height = std::sqrt(kBall * kBall - rho2) - trueSink + shownSink; // above the shown ball's centre
      sum += kBall - std::sqrt(rho2 + height * height);
      ++count;
    }
  }
  return sum / double(count);
}

/// `truth` after a displacement field that sends the intraoperative points 1-4 mm above the sunken
/// ball's top (in the frame of `rigid`: within 5 mm of the z axis, z' from 46 to 49 mm) to where
/// `truth` shows the preoperative ball's centre region (0, 0, 20): an island of brain in the gap.
itk::CompositeTransform<double, 3>::Pointer islandAbove(const itk::Transform<double, 3, 3>& truth, const itk::Euler3DTransform<double>& rigid)
{
  auto rigidInverse = itk::Euler3DTransform<double>::New();
  rigid.GetInverse(rigidInverse);
  const auto truthInverse = truth.GetInverseTransform();
  const PhysicalPoint target = truthInverse->TransformPoint(testing::point(0, 0, 20));
  PhysicalPoint low, high;
  for (unsigned a = 0; a < 3; ++a) {
    low[a] = 1e9;
    high[a] = -1e9;
  }
  for (double x : {-6.0, 6.0}) {
    for (double y : {-6.0, 6.0}) {
      for (double z : {44.0, 51.0}) {
        const PhysicalPoint corner = rigidInverse->TransformPoint(testing::point(x, y, z));
        for (unsigned a = 0; a < 3; ++a) {
          low[a] = std::min(low[a], corner[a]);
          high[a] = std::max(high[a], corner[a]);
        }
      }
    }
  }
  ScalarImage::SizeType size;
  for (unsigned a = 0; a < 3; ++a) size[a] = itk::SizeValueType(std::ceil((high[a] - low[a]) / 0.5)) + 1;
  auto field = testing::makeImage<itk::Image<itk::Vector<double, 3>, 3>>(testing::grid(size, {0.5, 0.5, 0.5}, low));
  itk::ImageRegionIteratorWithIndex<itk::Image<itk::Vector<double, 3>, 3>> it(field, field->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint y;
    field->TransformIndexToPhysicalPoint(it.GetIndex(), y);
    const PhysicalPoint frame = rigid.TransformPoint(y);
    itk::Vector<double, 3> d;
    d.Fill(0.0);
    if (std::hypot(frame[0], frame[1]) < 5.0 && frame[2] >= 46.0 && frame[2] <= 49.0) d = target - y;
    it.Set(d);
  }
  auto displacement = itk::DisplacementFieldTransform<double, 3>::New();
  displacement->SetDisplacementField(field);
  auto composite = itk::CompositeTransform<double, 3>::New();
  composite->AddTransform(const_cast<itk::Transform<double, 3, 3>*>(&truth)); // applied second
  composite->AddTransform(displacement);                                     // applied first
  return composite;
}

/// Nodes on the preoperative ball: 40 under the craniotomy (within 25 mm of the axis, on top), moved
/// by `topDisplacement` along z, and 20 on the side and below, moved 30 mm (not counted), and 5 not imposed.
vtkSmartPointer<vtkPolyData> ballNodes(double topDisplacement)
{
  auto points = vtkSmartPointer<vtkPoints>::New();
  auto displacement = vtkSmartPointer<vtkDoubleArray>::New();
  displacement->SetName("Displacement");
  displacement->SetNumberOfComponents(3);
  auto imposed = vtkSmartPointer<vtkDoubleArray>::New();
  imposed->SetName("Imposed");
  auto add = [&](double polar, double azimuth, double u, bool isImposed) {
    const double x0[3] = {kBall * std::sin(polar) * std::cos(azimuth), kBall * std::sin(polar) * std::sin(azimuth), kBall * std::cos(polar)};
    points->InsertNextPoint(x0[0], x0[1], x0[2] + u);
    displacement->InsertNextTuple3(0, 0, u);
    imposed->InsertNextValue(isImposed ? 1.0 : 0.0);
  };
  for (int k = 0; k < 40; ++k) add(std::asin(25.0 / kBall) * double(k % 8) / 7.0, 0.7 * k, topDisplacement, true);
  for (int k = 0; k < 20; ++k) add(1.2 + 0.1 * double(k % 10), 0.9 * k, 30.0, true);
  for (int k = 0; k < 5; ++k) add(0.1, 1.3 * k, 30.0, false);
  auto surface = vtkSmartPointer<vtkPolyData>::New();
  surface->SetPoints(points);
  surface->GetPointData()->AddArray(displacement);
  surface->GetPointData()->AddArray(imposed);
  return surface;
}
} // namespace

int CraniotomyBoundaryEvaluationTest(int, char*[])
{
  return brainshift::testing::runTest("CraniotomyBoundaryEvaluationTest", [] {
    const ImageGeometry grid = testing::grid({{120, 120, 120}}, {1.0, 1.0, 1.0}, testing::point(-59.5, -59.5, -59.5));
    const auto labels = testing::imageOn<LabelImage>(grid, [](const PhysicalPoint& p) {
      return LabelPixel(p[0] * p[0] + p[1] * p[1] + p[2] * p[2] < kBall * kBall ? 2 : 1);
    });
    CraniotomyFootprint footprint;
    footprint.centre = testing::point(0, 0, kBall);
    footprint.outwardAxis = {0, 0, 1};
    const auto rigid = testing::makeRigidTransform();
    const auto truth = sunkBy(5.0);
    const CraniotomyBoundaryEvaluation evaluation(*labels, *truth, *rigid, footprint);

    std::size_t lines = 0;
    const double rigidExpected = expectedMean(5.0, 0.0, lines);
    BS_CHECK(evaluation.trueBoundaryPoints() == lines); // every line within 30 mm, none beyond
    const CraniotomyBoundaryEvaluation::ShownBoundary rigidBothWays = evaluation.shownBoundary(*rigid);
    const BoundaryDistances& shownRigid = rigidBothWays.toShown;
    std::cout << "rigid: " << shownRigid.points << " points, signed " << shownRigid.signedMeanMm << ", mean " << shownRigid.meanAbsMm
              << " (expected " << rigidExpected << "), p95 " << shownRigid.p95AbsMm << ", max " << shownRigid.maxAbsMm << '\n';
    BS_CHECK(shownRigid.points == lines);
    BS_CHECK_NEAR(shownRigid.meanAbsMm, rigidExpected, 0.15);
    BS_CHECK_NEAR(shownRigid.signedMeanMm, rigidExpected, 0.15); // shown outside: under-compensated
    BS_CHECK(shownRigid.maxAbsMm < 5.3 && shownRigid.p95AbsMm > 4.6);

    // From the shown points: the rigid boundary lies 5 mm above the sunken one under the opening.
    std::cout << "rigid, from the shown points: " << rigidBothWays.toTrue.points << " points, signed " << rigidBothWays.toTrue.signedMeanMm
              << ", mean " << rigidBothWays.toTrue.meanAbsMm << "; both ways " << rigidBothWays.symmetricMeanAbsMm() << '\n';
    BS_CHECK(rigidBothWays.toTrue.points == lines);
    BS_CHECK_NEAR(rigidBothWays.toTrue.signedMeanMm, rigidExpected, 0.3);
    BS_CHECK_NEAR(rigidBothWays.symmetricMeanAbsMm(), 0.5 * (rigidBothWays.toTrue.meanAbsMm + shownRigid.meanAbsMm), 1e-9);
    const BoundaryDistances partial = evaluation.shownBoundary(*sunkBy(2.0)).toShown;
    BS_CHECK_NEAR(partial.signedMeanMm, expectedMean(5.0, 2.0, lines), 0.15);
    const BoundaryDistances overshoot = evaluation.shownBoundary(*sunkBy(7.0)).toShown;
    std::cout << "2 mm shown: " << partial.signedMeanMm << "; 7 mm shown: " << overshoot.signedMeanMm << " (expected "
              << expectedMean(5.0, 7.0, lines) << ")\n";
    BS_CHECK_NEAR(overshoot.signedMeanMm, expectedMean(5.0, 7.0, lines), 0.15); // negative: the shown lies inside
    BS_CHECK(overshoot.signedMeanMm < -1.0);
    const CraniotomyBoundaryEvaluation::ShownBoundary exact = evaluation.shownBoundary(*truth);
    BS_CHECK(exact.toShown.points == lines && exact.toShown.maxAbsMm < 1e-3);
    BS_CHECK(exact.toTrue.points == lines && exact.toTrue.maxAbsMm < 1e-3);

    // The truth with an island: what lies 1-4 mm above the sunken boundary within 5 mm of the axis
    // is shown as deep brain (preoperative brain left in the gap). Seen from the true points the
    // island's walls are near; from the shown points, its top is 4 mm off.
    const auto island = islandAbove(*truth, *rigid);
    const CraniotomyBoundaryEvaluation::ShownBoundary withIsland = evaluation.shownBoundary(*island);
    std::cout << "island: from the true points mean " << withIsland.toShown.meanAbsMm << " max " << withIsland.toShown.maxAbsMm
              << "; from the shown points mean " << withIsland.toTrue.meanAbsMm << " max " << withIsland.toTrue.maxAbsMm << '\n';
    BS_CHECK(withIsland.toTrue.maxAbsMm > 3.5 && withIsland.toTrue.maxAbsMm < 4.5);
    BS_CHECK(withIsland.toTrue.signedMeanMm > 0.05); // outside the true brain
    BS_CHECK(withIsland.toTrue.meanAbsMm > withIsland.toShown.meanAbsMm);

    // Surface nodes: those under the craniotomy moved the true 5 mm (down: -5 z) land on the true boundary.
    const auto moved = ballNodes(-5.0);
    const BoundaryDistances nodes = evaluation.imposedNodes(moved, *rigid);
    const BoundaryDistances undeformed = evaluation.imposedNodes(moved, *rigid, true);
    std::cout << "nodes: " << nodes.points << " mean " << nodes.meanAbsMm << " p95 " << nodes.p95AbsMm << "; undeformed "
              << undeformed.signedMeanMm << '\n';
    BS_CHECK(nodes.points == 40 && undeformed.points == 40);
    BS_CHECK(nodes.meanAbsMm < 0.25 && nodes.p95AbsMm < 0.5);
    BS_CHECK(undeformed.signedMeanMm > 4.0 && undeformed.signedMeanMm < 5.2 && undeformed.maxAbsMm < 5.3);
    const BoundaryDistances short2 = evaluation.imposedNodes(ballNodes(-3.0), *rigid);
    BS_CHECK(short2.signedMeanMm > 1.5 && short2.signedMeanMm < 2.2); // 2 mm short along z: above the boundary
    BS_CHECK_THROWS(evaluation.imposedNodes(vtkSmartPointer<vtkPolyData>::New(), *rigid), std::invalid_argument, "Imposed");
  });
}
