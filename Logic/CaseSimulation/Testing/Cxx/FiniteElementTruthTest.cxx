// The finite element truth on a synthetic brain (an ellipsoid of parenchyma with a ventricle and a
// tumour, 2.5 mm voxels): the boundary conditions hold in CalculiX's solution (sliding nodes move
// tangentially, and some of them by millimetres; the skull base stays; the cap sinks by the shift), the
// resampling field inverts the forward map, the gap under the craniotomy maps outside the preoperative
// brain, far from the brain w = 0, two runs are equal, and a missing or failing ccx is reported.
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "FiniteElementTruth.h"
#include "SyntheticData.h"

#include <itkVectorLinearInterpolateImageFunction.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <set>

namespace {
using namespace brainshift;
using Vec3 = std::array<double, 3>;
using Field = itk::Image<itk::Vector<double, 3>, 3>;
Vec3 add(const Vec3& a, const Vec3& b, double s = 1) { return {a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]}; }
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double norm(const Vec3& a) { return std::sqrt(dot(a, a)); }

// An ellipsoidal brain (semi-axes 38, 46, 34 mm) in a 6 mm head, a ventricle and a tumour under the craniotomy.
const Vec3 brainCentre{0, 0, 0};
bool inEllipsoid(const Vec3& p, const Vec3& c, const Vec3& semi)
{
  double s = 0;
  for (int d = 0; d < 3; ++d) s += std::pow((p[std::size_t(d)] - c[std::size_t(d)]) / semi[std::size_t(d)], 2);
  return s <= 1;
}
LabelImage::Pointer syntheticBrain()
{
  const auto geometry = testing::grid({44, 52, 40}, {2.5, 2.5, 2.5}, testing::point(-53.75, -63.75, -48.75));
  return testing::imageOn<LabelImage>(geometry, [](const PhysicalPoint& q) -> LabelPixel {
    const Vec3 p{q[0], q[1], q[2]};
    if (inEllipsoid(p, {-14, 0, 16}, {7, 7, 7})) return 4;
    if (inEllipsoid(p, {4, 0, 0}, {7, 16, 6})) return 3;
    if (inEllipsoid(p, brainCentre, {38, 46, 34})) return 2;
    return inEllipsoid(p, brainCentre, {44, 52, 40}) ? 1 : 0;
  });
}

FiniteElementTruthParameters syntheticParameters(const LabelImage& labels)
{
  FiniteElementTruthParameters P;
  const double s = 1 / std::sqrt(2.0);
  P.craniotomyAxis = {-s, 0, s}; // right (-L) and superior
  Vec3 centre = brainCentre;     // where the axis leaves the brain
  for (double t = 0; t < 80; t += 0.1) {
    const Vec3 p = add(brainCentre, P.craniotomyAxis, t);
    LabelImage::IndexType index;
    if (labels.TransformPhysicalPointToIndex(testing::point(p[0], p[1], p[2]), index) && labels.GetPixel(index) >= 2) centre = p;
  }
  P.craniotomyCentre = centre;
  // The built-in case's load (10 mm, sigma 25 mm, opening 30 mm on a 1,700 ml brain) scaled to this
  // 250 ml brain, so that the volume pushed in is a similar fraction of it.
  P.shiftMm = 6;
  P.lateralSigmaMm = 15;
  P.openingRadiusMm = 18;
  P.elementSizeMm = 6;
  return P;
}

Field::Pointer fieldOn(const LabelImage& labels, double spacing)
{
  const auto size = labels.GetLargestPossibleRegion().GetSize();
  const double extent[3] = {2.5 * double(size[0] - 1), 2.5 * double(size[1] - 1), 2.5 * double(size[2] - 1)};
  ScalarImage::SizeType fieldSize;
  for (int d = 0; d < 3; ++d) fieldSize[d] = std::size_t(std::ceil(extent[d] / spacing)) + 1;
  const auto origin = labels.GetOrigin();
  return testing::makeImage<Field>(testing::grid(fieldSize, {spacing, spacing, spacing}, testing::point(origin[0], origin[1], origin[2])));
}

LabelPixel labelAt(const LabelImage& labels, const Vec3& p)
{
  LabelImage::IndexType index;
  if (!labels.TransformPhysicalPointToIndex(testing::point(p[0], p[1], p[2]), index)) return 0;
  return labels.GetPixel(index);
}

/// (a) (b) (c): the boundary conditions in the solution, and the cap's pull reaching inside.
void checkBoundaryConditions(const FiniteElementTruthModel& model, const FiniteElementDisplacement& u, const FiniteElementTruthParameters& P)
{
  using Role = FiniteElementTruthModel::Role;
  double worstNormal = 0, largestSliding = 0, largestFixed = 0, capCentreSink = 0, nearest = INFINITY;
  for (std::size_t v = 0; v < model.nodes.size(); ++v) {
    const Vec3& d = model.displacements[v];
    if (model.roles[v] == Role::Sliding) {
      worstNormal = std::max(worstNormal, std::abs(dot(d, model.normals[v])) / std::max(norm(d), 1e-3));
      largestSliding = std::max(largestSliding, norm(d));
    }
    if (model.roles[v] == Role::Fixed) largestFixed = std::max(largestFixed, norm(d));
    const double distance = norm(add(model.nodes[v], P.craniotomyCentre, -1));
    if (model.roles[v] == Role::Loaded && distance < nearest) nearest = distance, capCentreSink = -dot(d, P.craniotomyAxis);
  }
  std::cout << "sliding: worst |u.n|/|u| " << worstNormal << ", largest |u| " << largestSliding << " mm; fixed: largest |u| "
            << largestFixed << " mm; cap node " << nearest << " mm from the centre sinks " << capCentreSink << " mm\n";
  BS_CHECK_MSG(worstNormal < 1e-3, "a sliding node leaves the skull: |u.n| / |u| = " << worstNormal);
  BS_CHECK_MSG(largestSliding > 1.0, "no sliding: the largest tangential motion is " << largestSliding << " mm");
  BS_CHECK(largestFixed < 1e-9);
  BS_CHECK(nearest < 0.5 * P.elementSizeMm);
  BS_CHECK_NEAR(capCentreSink, P.shiftMm, 0.03 * P.shiftMm);
  // The tissue 6 mm under the cap follows it (the solve, not just the imposed values).
  const auto below = u.at(add(P.craniotomyCentre, P.craniotomyAxis, -6));
  BS_CHECK(below.has_value());
  const double sinkBelow = -dot(*below, P.craniotomyAxis);
  std::cout << "6 mm under the cap's centre the tissue sinks " << sinkBelow << " mm\n";
  BS_CHECK_MSG(sinkBelow > 0.5 * P.shiftMm && sinkBelow < 1.05 * P.shiftMm, "under the cap: " << sinkBelow << " mm");
}

/// Whether the tissue within `margin` of X (along the axes) is `allowed` tissue.
bool surroundedBy(const LabelImage& labels, const Vec3& X, double margin, const std::set<int>& allowed)
{
  for (int d = 0; d < 3; ++d) {
    for (double s : {-margin, margin}) {
      Vec3 p = X;
      p[std::size_t(d)] += s;
      if (!allowed.count(labelAt(labels, p))) return false;
    }
  }
  return true;
}

/// (d): x' = X + u(X) maps back to X: exactly (the inversion), at the field's own grid points, and through
/// the trilinearly sampled field away from the two places where w bends sharply on the scale of the
/// grid (the rim of the cap, where the imposed sinking meets the sliding surface, and the soft ventricles).
void checkInversion(const LabelImage& labels, const FiniteElementDisplacement& u, const Field& field, const FiniteElementTruthParameters& P)
{
  auto interpolator = itk::VectorLinearInterpolateImageFunction<Field, double>::New();
  interpolator->SetInputImage(&field);
  double worstExact = 0, worstSmooth = 0, worstAny = 0, sumAny = 0;
  std::size_t count = 0, smooth = 0;
  itk::ImageRegionConstIteratorWithIndex<LabelImage> it(&labels, labels.GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint q;
    labels.TransformIndexToPhysicalPoint(it.GetIndex(), q);
    const Vec3 X{q[0], q[1], q[2]};
    const auto displacement = u.at(X);
    if (it.Get() < 2 || !displacement || !surroundedBy(labels, X, 5.0, {2, 3, 4})) continue;
    const Vec3 x = add(X, *displacement);
    const auto back = u.preoperativePosition(x);
    BS_CHECK_MSG(back.has_value(), "the deformed point of an interior point is not in the deformed brain");
    worstExact = std::max(worstExact, norm(add(back->preoperative, X, -1)));
    const auto w = interpolator->Evaluate(testing::point(x[0], x[1], x[2]));
    const double error = norm(add(add(x, {w[0], w[1], w[2]}), X, -1));
    worstAny = std::max(worstAny, error), sumAny += error, ++count;
    const Vec3 d = add(X, P.craniotomyCentre, -1);
    const double along = dot(d, P.craniotomyAxis), r = std::sqrt(std::max(dot(d, d) - along * along, 0.0));
    if (std::abs(r - P.openingRadiusMm) < 12.0 || !surroundedBy(labels, X, 5.0, {2, 4})) continue;
    worstSmooth = std::max(worstSmooth, error), ++smooth;
  }
  std::cout << count << " interior points: exact inversion error " << worstExact << " mm; through the field (2 mm grid, trilinear) mean "
            << sumAny / double(count) << ", max " << worstAny << " mm; max " << worstSmooth << " mm at the " << smooth
            << " away from the cap's rim and the ventricles\n";
  BS_CHECK(count > 1000 && smooth > 500);
  BS_CHECK(worstExact < 1e-4);
  BS_CHECK_MSG(sumAny / double(count) < 0.05, "the field's inverse is off by " << sumAny / double(count) << " mm on average");
  BS_CHECK_MSG(worstSmooth < 0.05, "the field's inverse is off by " << worstSmooth << " mm");
  // At the field's own points inside the deformed brain: X = x' + w(x') goes back to x' exactly.
  double worstAtNodes = 0;
  std::size_t inside = 0, outsideMesh = 0; // x' + w(x') a hair outside the straight preoperative elements (the boundary's curvature)
  itk::ImageRegionConstIteratorWithIndex<Field> node(&field, field.GetLargestPossibleRegion());
  for (; !node.IsAtEnd(); ++node) {
    PhysicalPoint q;
    field.TransformIndexToPhysicalPoint(node.GetIndex(), q);
    const Vec3 x{q[0], q[1], q[2]};
    if (!u.preoperativePosition(x)) continue;
    const Vec3 X = add(x, {node.Get()[0], node.Get()[1], node.Get()[2]});
    const auto displacement = u.at(X);
    ++inside;
    if (!displacement) {
      ++outsideMesh;
      continue;
    }
    worstAtNodes = std::max(worstAtNodes, norm(add(add(X, *displacement), x, -1)));
  }
  std::cout << "at the " << inside << " field points in the deformed brain: |X + u(X) - x'| <= " << worstAtNodes << " mm ("
            << outsideMesh << " with X just outside the mesh)\n";
  BS_CHECK(worstAtNodes < 1e-4);
  BS_CHECK(inside > 10000 && outsideMesh < inside / 100);
}

/// (e): the gap under the craniotomy maps outside the preoperative brain; far away w = 0.
void checkGapAndFarField(const LabelImage& labels, const FiniteElementDisplacement& u, const Field& field, const FiniteElementTruthParameters& P)
{
  auto interpolator = itk::VectorLinearInterpolateImageFunction<Field, double>::New();
  interpolator->SetInputImage(&field);
  std::size_t gap = 0, wrong = 0;
  itk::ImageRegionConstIteratorWithIndex<LabelImage> it(&labels, labels.GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint q;
    labels.TransformIndexToPhysicalPoint(it.GetIndex(), q);
    const Vec3 x{q[0], q[1], q[2]};
    const Vec3 d = add(x, P.craniotomyCentre, -1);
    const double along = dot(d, P.craniotomyAxis), r = std::sqrt(std::max(dot(d, d) - along * along, 0.0));
    // The gap: under the cap (not the far side of the brain), and at least one voxel (2.5 mm along the axis)
    // above the sunken surface: within a voxel of it the preoperative voxels' staircase and CGAL's surface
    // (within 1.5 mm of it) disagree by about that much.
    if (it.Get() < 2 || r > 0.8 * P.openingRadiusMm || along < -P.openingRadiusMm || u.preoperativePosition(x) ||
        u.preoperativePosition(add(x, P.craniotomyAxis, -2.5))) {
      continue;
    }
    const auto w = interpolator->Evaluate(q);
    ++gap;
    wrong += labelAt(labels, add(x, {w[0], w[1], w[2]})) >= 2;
  }
  std::cout << gap << " gap voxels under the craniotomy, " << wrong << " of them mapped into the preoperative brain\n";
  BS_CHECK(gap > 50);
  BS_CHECK_MSG(wrong == 0, wrong << " gap voxels map into the preoperative brain");
  // A corner of the field is far (> 40 mm) from the brain.
  const Field::IndexType corner{{0, 0, 0}};
  BS_CHECK(field.GetPixel(corner).GetNorm() == 0);
}

void checkFailures(FiniteElementTruthModel model, const FiniteElementTruthParameters& P)
{
  const std::string path = std::getenv("PATH") ? std::getenv("PATH") : "";
  const auto folder = testing::temporaryFolder("FiniteElementTruthFakeCcx");
  {
    std::ofstream script(folder / "ccx");
    script << "#!/bin/sh\necho 'reading the deck'\necho '*ERROR reading *EQUATION: something broke'\nexit 201\n";
  }
  std::filesystem::permissions(folder / "ccx", std::filesystem::perms::owner_all);
  FiniteElementTruthFigures figures;
  ::setenv("PATH", folder.c_str(), 1);
  BS_CHECK_THROWS(solveFiniteElementTruthModel(model, P, figures), MethodError, "something broke");
  ::setenv("PATH", (folder / "none").c_str(), 1);
  BS_CHECK_THROWS(solveFiniteElementTruthModel(model, P, figures), NotAvailableError, "calculix-ccx");
  ::setenv("PATH", path.c_str(), 1);
  FiniteElementTruthParameters bad = P;
  bad.craniotomyAxis = {0, 0, 2};
  BS_CHECK_THROWS(bad.validate(), InputError, "unit vector");
}
} // namespace

int FiniteElementTruthTest(int, char*[])
{
  return brainshift::testing::runTest("FiniteElementTruthTest", [] {
    const LabelImage::Pointer labels = syntheticBrain();
    FiniteElementTruthParameters P = syntheticParameters(*labels);
    P.workFolder = testing::temporaryFolder("FiniteElementTruthTest");
    FiniteElementTruthFigures figures;
    FiniteElementTruthModel model = buildFiniteElementTruthModel(*labels, P, &figures);
    solveFiniteElementTruthModel(model, P, figures);
    BS_CHECK(std::filesystem::exists(P.workFolder / "truth.inp")); // the caller's folder is kept
    const Field::Pointer field = fieldOn(*labels, 2.0);
    fillFiniteElementResamplingField(model, *field, P, figures);
    std::cout << figures.nodes << " nodes, " << figures.elements << " C3D10 (" << figures.droppedElements << " dropped); "
              << figures.slidingNodes << " sliding, " << figures.fixedNodes << " fixed, " << figures.loadedNodes
              << " loaded; mesh " << figures.meshSeconds << " s, ccx " << figures.ccxSeconds << " s, " << figures.ccxPeakMemoryMb
              << " MB; field " << figures.fieldSeconds << " s (" << figures.newtonFallbacks << " Newton, "
              << figures.unconvergedInversions << " unconverged); max |u| " << figures.maxDisplacementMm << " mm; " << figures.invertedElements << " inverted\n";
    BS_CHECK(figures.elements > 500 && figures.slidingNodes > 100 && figures.fixedNodes > 20 && figures.loadedNodes > 20);
    BS_CHECK(figures.unconvergedInversions == 0);
    std::set<int> tissues(model.labels.begin(), model.labels.end());
    BS_CHECK(tissues == std::set<int>({2, 3, 4}));
    const FiniteElementDisplacement u(model);
    checkBoundaryConditions(model, u, P);
    checkInversion(*labels, u, *field, P);
    checkGapAndFarField(*labels, u, *field, P);

    // (f) Determinism: the whole function again (in a temporary folder) gives the same field, bit for bit.
    FiniteElementTruthParameters again = P;
    again.workFolder.clear();
    const Field::Pointer second = fieldOn(*labels, 2.0);
    const FiniteElementTruthFigures secondFigures = solveFiniteElementTruth(*labels, *second, again);
    BS_CHECK(secondFigures.nodes == figures.nodes && secondFigures.elements == figures.elements);
    BS_CHECK(std::memcmp(field->GetBufferPointer(), second->GetBufferPointer(),
                         field->GetLargestPossibleRegion().GetNumberOfPixels() * sizeof(itk::Vector<double, 3>)) == 0);

    checkFailures(model, P);
  });
}
