#include "SurfaceDisplacementEvaluation.h"

#include "DistanceMaps.h"

#include <itkLinearInterpolateImageFunction.h>

#include <vtkDataArray.h>
#include <vtkPointData.h>

// ITK brings its own Eigen; a second copy in the same translation unit clashes.
#include <itk_eigen.h>
#include ITK_EIGEN(Dense)

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace brainshift {

namespace {
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
} // namespace

SurfaceDisplacementAccuracy evaluateSurfaceDisplacement(vtkPolyData* surface, const SpatialTransform& truth,
                                                        const SpatialTransform& rigidUsed, const LabelImage& preopLabels,
                                                        const std::set<LabelPixel>& brainLabels)
{
  vtkDataArray* displacement = surface->GetPointData()->GetArray("Displacement");
  vtkDataArray* imposed = surface->GetPointData()->GetArray("Imposed");
  if (!displacement || displacement->GetNumberOfComponents() != 3 || !imposed) {
    throw std::invalid_argument("the surface has no point arrays \"Displacement\" (3 components) and \"Imposed\"");
  }
  const AffineParameters rigid = affineParametersOf(&rigidUsed);
  Eigen::Matrix3d A;
  Vec t;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) A(i, j) = rigid.matrix[i][j];
    t[i] = rigid.translation[i];
  }
  const Eigen::Matrix3d Ainverse = A.inverse();

  // The preoperative brain's boundary distance (zero level on the voxel faces).
  auto mask = MaskImage::New();
  mask->SetRegions(preopLabels.GetLargestPossibleRegion());
  mask->CopyInformation(&preopLabels);
  mask->Allocate();
  const LabelPixel* l = preopLabels.GetBufferPointer();
  unsigned char* m = mask->GetBufferPointer();
  for (std::size_t i = 0, n = preopLabels.GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) m[i] = brainLabels.count(l[i]) ? 1 : 0;
  const ScalarImage::Pointer distance = boundaryDistanceMm(mask);
  auto interpolator = itk::LinearInterpolateImageFunction<ScalarImage, double>::New();
  interpolator->SetInputImage(distance);

  SurfaceDisplacementAccuracy a;
  std::vector<double> errors, trueMagnitudes, residuals;
  for (vtkIdType i = 0; i < surface->GetNumberOfPoints(); ++i) {
    if (imposed->GetComponent(i, 0) < 0.5) continue;
    Vec x1, u;
    surface->GetPoint(i, x1.data());
    displacement->GetTuple(i, u.data());
    const Vec x0 = x1 - u;
    // y with T(y) = x0: Newton-like steps with the rigid part's matrix as the Jacobian.
    Vec y = Ainverse * (x0 - t);
    for (int k = 0; k < 50; ++k) {
      const Vec r = x0 - toVec(truth.TransformPoint(toPoint(y)));
      y += Ainverse * r;
      if (r.norm() < 1e-6) break;
    }
    const Vec trueDisplacement = (A * y + t) - x0;
    errors.push_back((u - trueDisplacement).norm());
    trueMagnitudes.push_back(trueDisplacement.norm());
    // Where the node ends against the true intraoperative boundary (through the truth, on the
    // fine preoperative grid), against where it started from the preoperative boundary.
    itk::ContinuousIndex<double, 3> end, start;
    distance->TransformPhysicalPointToContinuousIndex(truth.TransformPoint(toPoint(Ainverse * (x1 - t))), end);
    distance->TransformPhysicalPointToContinuousIndex(toPoint(x0), start);
    if (interpolator->IsInsideBuffer(end) && interpolator->IsInsideBuffer(start)) {
      residuals.push_back(std::abs(interpolator->EvaluateAtContinuousIndex(end) - interpolator->EvaluateAtContinuousIndex(start)));
    }
  }
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
