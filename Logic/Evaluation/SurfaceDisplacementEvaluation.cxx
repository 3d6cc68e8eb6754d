#include "SurfaceDisplacementEvaluation.h"

#include "DistanceMaps.h"

#include <itkLinearInterpolateImageFunction.h>

#include <vtkCellArray.h>
#include <vtkCellLocator.h>
#include <vtkDataArray.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkSmartPointer.h>

// ITK brings its own Eigen; a second copy in the same translation unit clashes.
#include <itk_eigen.h>
#include ITK_EIGEN(Dense)

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

namespace brainshift {
namespace {
/// The signed distance to the boundary of `brainLabels` in `labels` (zero level on the voxel faces).
ScalarImage::Pointer brainBoundaryDistanceMm(const LabelImage& labels, const std::set<LabelPixel>& brainLabels)
{
  auto mask = MaskImage::New();
  mask->SetRegions(labels.GetLargestPossibleRegion());
  mask->CopyInformation(&labels);
  mask->Allocate();
  const LabelPixel* l = labels.GetBufferPointer();
  unsigned char* m = mask->GetBufferPointer();
  for (std::size_t i = 0, n = labels.GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) m[i] = brainLabels.count(l[i]) ? 1 : 0;
  return boundaryDistanceMm(mask);
}

using Vec = Eigen::Vector3d;

Vec toVec(const PhysicalPoint& p) { return {p[0], p[1], p[2]}; }
PhysicalPoint toPoint(const Vec& v)
{
  PhysicalPoint p;
  for (unsigned i = 0; i < 3; ++i) p[i] = v[int(i)];
  return p;
}

double percentile(std::vector<double> values, double p)
{
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  const double rank = p * double(values.size() - 1);
  const std::size_t below = std::size_t(std::floor(rank)), above = std::min(values.size() - 1, below + 1);
  return values[below] + (rank - double(below)) * (values[above] - values[below]);
}

double mean(const std::vector<double>& values)
{
  double sum = 0;
  for (double v : values) sum += v;
  return values.empty() ? 0 : sum / double(values.size());
}

/// y -> A y + t and its inverse, of a linear transform.
struct AffineMap {
  Eigen::Matrix3d A = Eigen::Matrix3d::Identity();
  Vec t = Vec::Zero();
  Vec operator()(const Vec& y) const { return A * y + t; }
  AffineMap inverse() const
  {
    AffineMap m;
    m.A = A.inverse();
    m.t = -(m.A * t);
    return m;
  }
};

AffineMap affineMapOf(const SpatialTransform& transform)
{
  const AffineParameters p = affineParametersOf(&transform);
  AffineMap m;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) m.A(i, j) = p.matrix[i][j];
    m.t[i] = p.translation[i];
  }
  return m;
}

/// Calls visit(x0, x1, u) for every imposed node of the active surface: its preoperative place
/// x0, its deformed place x1 = x0 + u (the model's frame). std::invalid_argument without the
/// surface's "Displacement" (3 components) and "Imposed" point arrays.
template <typename Visit>
void forEachImposedNode(vtkPolyData* surface, Visit&& visit)
{
  vtkDataArray* displacement = surface->GetPointData()->GetArray("Displacement");
  vtkDataArray* imposed = surface->GetPointData()->GetArray("Imposed");
  if (!displacement || displacement->GetNumberOfComponents() != 3 || !imposed) {
    throw std::invalid_argument("the surface has no point arrays \"Displacement\" (3 components) and \"Imposed\"");
  }
  for (vtkIdType i = 0; i < surface->GetNumberOfPoints(); ++i) {
    if (imposed->GetComponent(i, 0) < 0.5) continue;
    Vec x1, u;
    surface->GetPoint(i, x1.data());
    displacement->GetTuple(i, u.data());
    visit(Vec(x1 - u), x1, u);
  }
}
} // namespace

SurfaceDisplacementAccuracy evaluateSurfaceDisplacement(vtkPolyData* surface, const SpatialTransform& truth,
                                                        const SpatialTransform& rigidUsed, const LabelImage& preopLabels,
                                                        const std::set<LabelPixel>& brainLabels)
{
  const AffineMap rigid = affineMapOf(rigidUsed), rigidInverse = rigid.inverse();

  // The preoperative brain's boundary distance (zero level on the voxel faces).
  const ScalarImage::Pointer distance = brainBoundaryDistanceMm(preopLabels, brainLabels);
  auto interpolator = itk::LinearInterpolateImageFunction<ScalarImage, double>::New();
  interpolator->SetInputImage(distance);

  SurfaceDisplacementAccuracy a;
  std::vector<double> errors, trueMagnitudes, residuals;
  forEachImposedNode(surface, [&](const Vec& x0, const Vec& x1, const Vec& u) {
    // y with T(y) = x0: Newton-like steps with the rigid part's matrix as the Jacobian.
    Vec y = rigidInverse(x0);
    for (int k = 0; k < 50; ++k) {
      const Vec r = x0 - toVec(truth.TransformPoint(toPoint(y)));
      y += rigidInverse.A * r;
      if (r.norm() < 1e-6) break;
    }
    const Vec trueDisplacement = rigid(y) - x0;
    errors.push_back((u - trueDisplacement).norm());
    trueMagnitudes.push_back(trueDisplacement.norm());
    // Where the node ends against the true intraoperative boundary (through the truth, on the
    // fine preoperative grid), against where it started from the preoperative boundary.
    itk::ContinuousIndex<double, 3> end, start;
    distance->TransformPhysicalPointToContinuousIndex(truth.TransformPoint(toPoint(rigidInverse(x1))), end);
    distance->TransformPhysicalPointToContinuousIndex(toPoint(x0), start);
    if (interpolator->IsInsideBuffer(end) && interpolator->IsInsideBuffer(start)) {
      residuals.push_back(std::abs(interpolator->EvaluateAtContinuousIndex(end) - interpolator->EvaluateAtContinuousIndex(start)));
    }
  });
  a.nodes = errors.size();
  if (errors.empty()) return a;
  a.meanErrorMm = mean(errors);
  a.medianErrorMm = percentile(errors, 0.5);
  a.p95ErrorMm = percentile(errors, 0.95);
  a.maxErrorMm = *std::max_element(errors.begin(), errors.end());
  a.meanTrueDisplacementMm = mean(trueMagnitudes);
  a.maxTrueDisplacementMm = *std::max_element(trueMagnitudes.begin(), trueMagnitudes.end());
  std::vector<double> movingErrors, movingTrue;
  for (std::size_t i = 0; i < errors.size(); ++i) {
    if (trueMagnitudes[i] <= 2.0) continue;
    movingErrors.push_back(errors[i]);
    movingTrue.push_back(trueMagnitudes[i]);
  }
  a.movingNodes = movingErrors.size();
  a.movingMeanErrorMm = mean(movingErrors);
  a.movingP95ErrorMm = percentile(movingErrors, 0.95);
  a.movingMeanTrueDisplacementMm = mean(movingTrue);
  a.meanResidualMm = mean(residuals);
  a.p95ResidualMm = percentile(residuals, 0.95);
  return a;
}

} // namespace brainshift

// ---- The brain boundary under the craniotomy ------------------------------------------------------

namespace brainshift {

namespace {
BoundaryDistances distancesOf(const std::vector<double>& signedMm)
{
  BoundaryDistances b;
  b.points = signedMm.size();
  if (signedMm.empty()) return b;
  std::vector<double> magnitudes;
  for (double v : signedMm) magnitudes.push_back(std::abs(v));
  b.signedMeanMm = mean(signedMm);
  b.meanAbsMm = mean(magnitudes);
  b.p95AbsMm = percentile(magnitudes, 0.95);
  b.maxAbsMm = *std::max_element(magnitudes.begin(), magnitudes.end());
  return b;
}

constexpr double kLineSpacingMm = 1.0, kMarginMm = 15.0, kTopMm = 40.0, kBottomMm = -80.0;

/// The first s (from kTopMm down to kBottomMm) where inside(origin + s axis) turns <= 0, NaN if
/// none or if the line starts inside. `inside` is a signed distance in mm (or close to one):
/// steps of half its value, at least 0.25 mm, then bisection.
template <typename F>
double firstEntry(const F& inside, const Vec& origin, const Vec& axis)
{
  double s = kTopMm, v = inside(origin + s * axis);
  if (!(v > 0)) return std::nan("");
  while (s > kBottomMm) {
    const double next = std::max(s - std::max(0.25, 0.5 * v), kBottomMm);
    const double w = inside(origin + next * axis);
    if (w <= 0) {
      double above = s, below = next;
      for (int k = 0; k < 40 && above - below > 1e-5; ++k) {
        const double mid = 0.5 * (above + below);
        (inside(origin + mid * axis) > 0 ? above : below) = mid;
      }
      return 0.5 * (above + below);
    }
    s = next;
    v = w;
  }
  return std::nan("");
}
} // namespace

struct CraniotomyBoundaryEvaluation::Data {
  ScalarImage::Pointer distance; ///< to the preoperative brain boundary, negative inside
  itk::LinearInterpolateImageFunction<ScalarImage, double>::Pointer interpolator;
  AffineMap trueRigid, trueRigidInverse; ///< intraop y -> frame x' and back
  const SpatialTransform* truth = nullptr;
  Vec centre, axis, e1, e2;
  double radius = 30, nodeDepth = 20;
  int half = 0; ///< lines (i, j), i, j in [-half, half], kLineSpacingMm apart
  vtkSmartPointer<vtkPolyData> trueSurface;
  vtkSmartPointer<vtkCellLocator> trueLocator;
  std::vector<Vec> truePoints; ///< of the true boundary, within the radius

  /// The preoperative signed distance at preoperative point x (outside the grid: outside, 2 mm).
  double distanceAt(const Vec& x) const
  {
    itk::ContinuousIndex<double, 3> index;
    distance->TransformPhysicalPointToContinuousIndex(toPoint(x), index);
    return interpolator->IsInsideBuffer(index) ? interpolator->EvaluateAtContinuousIndex(index) : 2.0;
  }
  /// The signed distance that `intraopToPreop` carries to x' of the frame.
  double carriedDistanceAt(const SpatialTransform& intraopToPreop, const Vec& xFrame) const
  {
    return distanceAt(toVec(intraopToPreop.TransformPoint(toPoint(trueRigidInverse(xFrame)))));
  }
  Vec lineOrigin(int i, int j) const { return centre + double(i) * kLineSpacingMm * e1 + double(j) * kLineSpacingMm * e2; }
  bool withinRadius(int i, int j) const { return double(i * i + j * j) * kLineSpacingMm * kLineSpacingMm <= radius * radius; }

  /// The height field of the boundary that `intraopToPreop` shows: its triangles, and the points of
  /// the lines within the radius when `pointsWithin` is given.
  vtkSmartPointer<vtkPolyData> boundarySurface(const SpatialTransform& intraopToPreop, std::vector<Vec>* pointsWithin) const;
  /// The distance of `p` (frame) to `surface`, signed by `outside` (> 0: positive).
  static double signedDistance(vtkCellLocator* locator, const Vec& p, bool outside)
  {
    double closest[3], squared = 0;
    vtkIdType cell = -1;
    int sub = 0;
    Vec q = p;
    locator->FindClosestPoint(q.data(), closest, cell, sub, squared);
    return (outside ? 1.0 : -1.0) * std::sqrt(squared);
  }
};

vtkSmartPointer<vtkPolyData> CraniotomyBoundaryEvaluation::Data::boundarySurface(const SpatialTransform& intraopToPreop,
                                                                                 std::vector<Vec>* pointsWithin) const
{
  const int n = 2 * half + 1;
  std::vector<vtkIdType> ids(std::size_t(n) * std::size_t(n), -1);
  auto points = vtkSmartPointer<vtkPoints>::New();
  const auto inside = [&](const Vec& x) { return carriedDistanceAt(intraopToPreop, x); };
  const double outer = radius + kMarginMm;
  for (int i = -half; i <= half; ++i) {
    for (int j = -half; j <= half; ++j) {
      if (double(i * i + j * j) * kLineSpacingMm * kLineSpacingMm > outer * outer) continue;
      const double s = firstEntry(inside, lineOrigin(i, j), axis);
      if (std::isnan(s)) continue;
      const Vec p = lineOrigin(i, j) + s * axis;
      ids[std::size_t(i + half) * std::size_t(n) + std::size_t(j + half)] = points->InsertNextPoint(p.data());
      if (pointsWithin && withinRadius(i, j)) pointsWithin->push_back(p);
    }
  }
  auto triangles = vtkSmartPointer<vtkCellArray>::New();
  const auto id = [&](int a, int b) { return ids[std::size_t(a) * std::size_t(n) + std::size_t(b)]; };
  for (int a = 0; a + 1 < n; ++a) {
    for (int b = 0; b + 1 < n; ++b) {
      const vtkIdType p00 = id(a, b), p10 = id(a + 1, b), p01 = id(a, b + 1), p11 = id(a + 1, b + 1);
      for (const std::array<vtkIdType, 3>& t : {std::array<vtkIdType, 3>{p00, p10, p11}, std::array<vtkIdType, 3>{p00, p11, p01}}) {
        if (t[0] >= 0 && t[1] >= 0 && t[2] >= 0) triangles->InsertNextCell(3, t.data());
      }
    }
  }
  auto surface = vtkSmartPointer<vtkPolyData>::New();
  surface->SetPoints(points);
  surface->SetPolys(triangles);
  return surface;
}

CraniotomyBoundaryEvaluation::CraniotomyBoundaryEvaluation(const LabelImage& preopLabels, const SpatialTransform& trueIntraopToPreop,
                                                           const SpatialTransform& trueRigidIntraopToPreop,
                                                           const CraniotomyFootprint& footprint, const std::set<LabelPixel>& brainLabels)
  : d(std::make_unique<Data>())
{
  d->distance = brainBoundaryDistanceMm(preopLabels, brainLabels);
  d->interpolator = itk::LinearInterpolateImageFunction<ScalarImage, double>::New();
  d->interpolator->SetInputImage(d->distance);
  d->trueRigid = affineMapOf(trueRigidIntraopToPreop);
  d->trueRigidInverse = d->trueRigid.inverse();
  d->truth = &trueIntraopToPreop;
  d->centre = toVec(footprint.centre);
  d->axis = Vec(footprint.outwardAxis[0], footprint.outwardAxis[1], footprint.outwardAxis[2]);
  if (!(d->axis.norm() > 0) || !(footprint.radiusMm > 0)) throw std::invalid_argument("the craniotomy footprint has no axis or no radius");
  d->axis.normalize();
  const Vec other = std::abs(d->axis[0]) < 0.9 ? Vec(1, 0, 0) : Vec(0, 1, 0);
  d->e1 = d->axis.cross(other).normalized();
  d->e2 = d->axis.cross(d->e1);
  d->radius = footprint.radiusMm;
  d->nodeDepth = footprint.nodeDepthMm;
  d->half = int(std::ceil((d->radius + kMarginMm) / kLineSpacingMm));
  d->trueSurface = d->boundarySurface(trueIntraopToPreop, &d->truePoints);
  d->trueLocator = vtkSmartPointer<vtkCellLocator>::New();
  d->trueLocator->SetDataSet(d->trueSurface);
  d->trueLocator->BuildLocator();
}

CraniotomyBoundaryEvaluation::~CraniotomyBoundaryEvaluation() = default;

std::size_t CraniotomyBoundaryEvaluation::trueBoundaryPoints() const { return d->truePoints.size(); }

double CraniotomyBoundaryEvaluation::ShownBoundary::symmetricMeanAbsMm() const
{
  if (toShown.points == 0 || toTrue.points == 0) return std::numeric_limits<double>::quiet_NaN(); // one way unmeasured
  const double points = double(toShown.points + toTrue.points);
  return (toShown.meanAbsMm * double(toShown.points) + toTrue.meanAbsMm * double(toTrue.points)) / points;
}

CraniotomyBoundaryEvaluation::ShownBoundary CraniotomyBoundaryEvaluation::shownBoundary(const SpatialTransform& intraopToPreop) const
{
  std::vector<Vec> shownPoints;
  const vtkSmartPointer<vtkPolyData> shown = d->boundarySurface(intraopToPreop, &shownPoints);
  if (shown->GetNumberOfCells() == 0) return {};
  auto locator = vtkSmartPointer<vtkCellLocator>::New();
  locator->SetDataSet(shown);
  locator->BuildLocator();
  ShownBoundary result;
  std::vector<double> distances;
  // A true point inside the shown brain: the shown boundary lies outside it (positive).
  for (const Vec& p : d->truePoints) distances.push_back(Data::signedDistance(locator, p, d->carriedDistanceAt(intraopToPreop, p) <= 0));
  result.toShown = distancesOf(distances);
  distances.clear();
  // A shown point outside the true brain: positive.
  for (const Vec& p : shownPoints) distances.push_back(Data::signedDistance(d->trueLocator, p, d->carriedDistanceAt(*d->truth, p) > 0));
  result.toTrue = distancesOf(distances);
  return result;
}

BoundaryDistances CraniotomyBoundaryEvaluation::imposedNodes(vtkPolyData* surface, const SpatialTransform& rigidUsed, bool undeformed) const
{
  const AffineMap modelToIntraop = affineMapOf(rigidUsed).inverse();
  std::vector<double> distances;
  forEachImposedNode(surface, [&](const Vec& x0, const Vec& x1, const Vec&) {
    const Vec fromCentre = x0 - d->centre;
    const double along = fromCentre.dot(d->axis);
    if (along < -d->nodeDepth || (fromCentre - along * d->axis).norm() > d->radius) return;
    const Vec frame = d->trueRigid(modelToIntraop(undeformed ? x0 : x1));
    const double toTrue = Data::signedDistance(d->trueLocator, frame, d->carriedDistanceAt(*d->truth, frame) > 0);
    distances.push_back(toTrue - d->distanceAt(x0));
  });
  return distancesOf(distances);
}

} // namespace brainshift
