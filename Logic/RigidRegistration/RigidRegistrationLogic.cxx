#include "RigidRegistrationLogic.h"

#include "Configuration.h"

#include "DeterministicMattesMetric.h"
#include "DistanceMaps.h"
#include "IntensityStatistics.h"
#include "LibraryMessages.h"

#include <itkBinShrinkImageFilter.h>
#include <itkCentralDifferenceImageFunction.h>
#include <itkCommand.h>
#include <itkEuler3DTransform.h>
#include <itkImageMaskSpatialObject.h>
#include <itkImageRegionConstIteratorWithIndex.h>
#include <itkLinearInterpolateImageFunction.h>
#include <itkMattesMutualInformationImageToImageMetricv4.h>
#include <itkMultiThreaderBase.h>
#include <itkRegistrationParameterScalesFromPhysicalShift.h>
#include <itkRegularStepGradientDescentOptimizerv4.h>
#include <itkVersorRigid3DTransform.h>

#include <algorithm>
#include <functional>
#include <limits>
#include <cmath>
#include <numeric>
#include <random>
#include <sstream>

namespace brainshift {

namespace {

using Transform = itk::VersorRigid3DTransform<double>;
using Metric = DeterministicMattesMetric<ScalarImage>;
using PointSet = Metric::FixedSampledPointSetType;
using Optimizer = itk::RegularStepGradientDescentOptimizerv4<double>;
using ScalesEstimator = itk::RegistrationParameterScalesFromPhysicalShift<Metric>;
using MaskObject = itk::ImageMaskSpatialObject<3>;
using Interpolator = itk::LinearInterpolateImageFunction<ScalarImage, double>;

constexpr double Degrees = 180.0 / M_PI;

/// Averages bins of voxels: the image at about `spacingMm`, never finer than it is.
ScalarImage::Pointer shrinkTo(const ScalarImage& image, double spacingMm)
{
  auto shrink = itk::BinShrinkImageFilter<ScalarImage, ScalarImage>::New();
  shrink->SetInput(&image);
  itk::BinShrinkImageFilter<ScalarImage, ScalarImage>::ShrinkFactorsType factors;
  bool any = false;
  for (unsigned i = 0; i < 3; ++i) {
    factors[i] = std::max(1u, unsigned(std::lround(spacingMm / image.GetSpacing()[i])));
    any = any || factors[i] > 1;
  }
  if (!any) return const_cast<ScalarImage*>(&image);
  shrink->SetShrinkFactors(factors);
  shrink->Update();
  ScalarImage::Pointer out = shrink->GetOutput();
  out->DisconnectPipeline();
  return out;
}

float maximumOf(const ScalarImage& image)
{
  const float* v = image.GetBufferPointer();
  return *std::max_element(v, v + image.GetLargestPossibleRegion().GetNumberOfPixels());
}

/// The foreground threshold of an MR image: half of Otsu's split between air and head, so that
/// dark tissue (CSF, bone next to scalp) counts.
double foregroundThreshold(const ScalarImage& image)
{
  const std::size_t n = image.GetLargestPossibleRegion().GetNumberOfPixels();
  return 0.5 * otsuThresholds(image.GetBufferPointer(), n, 2, 0.0, maximumOf(image))[0];
}

PhysicalPoint centroidOfForeground(const ScalarImage& image, double threshold, const std::function<bool(const PhysicalPoint&)>& keep)
{
  double sum[3] = {0, 0, 0}, count = 0;
  itk::ImageRegionConstIteratorWithIndex<ScalarImage> it(&image, image.GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    if (it.Get() <= threshold) continue;
    PhysicalPoint p;
    image.TransformIndexToPhysicalPoint(it.GetIndex(), p);
    if (keep && !keep(p)) continue;
    for (int i = 0; i < 3; ++i) sum[i] += p[i];
    count += 1;
  }
  PhysicalPoint c;
  for (int i = 0; i < 3; ++i) c[i] = count > 0 ? sum[i] / count : std::nan("");
  return c;
}

/// `count` random foreground points of `image` (seeded), jittered within their voxel so that the
/// samples do not sit on one grid.
PointSet::Pointer sampleForeground(const ScalarImage& image, double threshold, unsigned count, std::uint64_t seed)
{
  std::vector<std::size_t> candidates;
  const float* v = image.GetBufferPointer();
  const std::size_t n = image.GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) {
    if (v[i] > threshold) candidates.push_back(i);
  }
  std::mt19937_64 rng(seed);
  std::shuffle(candidates.begin(), candidates.end(), rng);
  candidates.resize(std::min<std::size_t>(candidates.size(), count));
  std::sort(candidates.begin(), candidates.end()); // memory order: faster interpolation
  std::uniform_real_distribution<double> jitter(-0.5, 0.5);
  auto points = PointSet::New();
  points->Initialize();
  const auto size = image.GetLargestPossibleRegion().GetSize();
  unsigned id = 0;
  for (std::size_t offset : candidates) {
    itk::ContinuousIndex<double, 3> index;
    index[0] = double(offset % size[0]) + jitter(rng);
    index[1] = double((offset / size[0]) % size[1]) + jitter(rng);
    index[2] = double(offset / (size[0] * size[1])) + jitter(rng);
    PointSet::PointType p;
    image.TransformContinuousIndexToPhysicalPoint(index, p);
    points->SetPoint(id++, p);
  }
  return points;
}

/// The preoperative mask as the metric asks it, once per sample and iteration: the answer of
/// ImageMaskSpatialObject (whose object space is the world's here: no transform is ever set on it)
/// without the identity transform to object space, the name test and the virtual calls it makes
/// on every question.
class PreoperativeMask : public MaskObject {
public:
  ITK_DISALLOW_COPY_AND_MOVE(PreoperativeMask);
  using Self = PreoperativeMask;
  using Superclass = MaskObject;
  using Pointer = itk::SmartPointer<Self>;
  itkNewMacro(Self);
  itkTypeMacro(PreoperativeMask, ImageMaskSpatialObject);

  bool IsInsideInWorldSpace(const PointType& point, unsigned int depth = 0, const std::string& name = "") const override
  {
    if (depth > 0 || !name.empty()) return Superclass::IsInsideInWorldSpace(point, depth, name);
    const ImageType* image = GetImage();
    const IndexType index = image->TransformPhysicalPointToIndex(point);
    return image->GetBufferedRegion().IsInside(index) && image->GetPixel(index) != 0;
  }

protected:
  PreoperativeMask() = default;
  ~PreoperativeMask() override = default;
};

/// The preoperative head and brain (labels >= 1), dilated, at 2 mm: where the metric may look.
MaskObject::Pointer movingMaskFrom(const LabelImage& labels, double dilationMm)
{
  auto mask = ScalarImage::New();
  mask->CopyInformation(&labels);
  mask->SetRegions(labels.GetLargestPossibleRegion());
  mask->Allocate();
  const LabelPixel* l = labels.GetBufferPointer();
  float* m = mask->GetBufferPointer();
  for (std::size_t i = 0, n = labels.GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) m[i] = l[i] >= 1 ? 1.f : 0.f;
  ScalarImage::Pointer coarse = shrinkTo(*mask, 2.0);
  auto binary = MaskImage::New();
  binary->CopyInformation(coarse);
  binary->SetRegions(coarse->GetLargestPossibleRegion());
  binary->Allocate();
  const std::size_t n = coarse->GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) binary->GetBufferPointer()[i] = coarse->GetBufferPointer()[i] > 0.0f;
  const ScalarImage::Pointer distance = signedDistanceMm(binary);
  for (std::size_t i = 0; i < n; ++i) binary->GetBufferPointer()[i] = distance->GetBufferPointer()[i] <= dilationMm;
  auto object = PreoperativeMask::New();
  object->SetImage(binary);
  object->Update();
  return object.GetPointer();
}

/// Whether `mask` leaves the intensity range of `image` whole: the lowest and highest voxel inside
/// it (found as ITK's Mattes metric finds them) are those of the whole image.
bool maskKeepsIntensityRange(const ScalarImage& image, const MaskObject& mask)
{
  const float* v = image.GetBufferPointer();
  const auto whole = std::minmax_element(v, v + image.GetLargestPossibleRegion().GetNumberOfPixels());
  float lowest = std::numeric_limits<float>::max(), highest = std::numeric_limits<float>::lowest();
  itk::ImageRegionConstIteratorWithIndex<ScalarImage> it(&image, image.GetBufferedRegion());
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint p;
    image.TransformIndexToPhysicalPoint(it.GetIndex(), p);
    if (!mask.IsInsideInWorldSpace(p)) continue;
    lowest = std::min(lowest, it.Get());
    highest = std::max(highest, it.Get());
  }
  return lowest == *whole.first && highest == *whole.second;
}

/// The moving image's gradient exactly as ITK's metric computes it by default (central differences
/// of linear interpolation half a voxel either side, zero where a neighbour leaves the buffer), with
/// each neighbour's continuous index computed once instead of twice and the interpolation called
/// directly: the gradient takes six of the metric's eight interpolations per sample.
class MovingImageGradient : public itk::CentralDifferenceImageFunction<ScalarImage, double> {
public:
  ITK_DISALLOW_COPY_AND_MOVE(MovingImageGradient);
  using Self = MovingImageGradient;
  using Superclass = itk::CentralDifferenceImageFunction<ScalarImage, double>;
  using Pointer = itk::SmartPointer<Self>;
  itkNewMacro(Self);
  itkTypeMacro(MovingImageGradient, CentralDifferenceImageFunction);

  void SetInputImage(const ScalarImage* image) override
  {
    Superclass::SetInputImage(image);
    linear->SetInputImage(image);
  }

  OutputType Evaluate(const PointType& point) const override
  {
    if (!this->GetUseImageDirection()) return Superclass::Evaluate(point);
    const ScalarImage* image = this->GetInputImage();
    OutputType derivative;
    for (unsigned dim = 0; dim < 3; ++dim) {
      derivative[dim] = 0.0;
      const double offset = 0.5 * image->GetSpacing()[dim];
      PointType below = point, above = point;
      below[dim] = point[dim] - offset;
      above[dim] = point[dim] + offset;
      ContinuousIndexType low, high;
      image->TransformPhysicalPointToContinuousIndex(below, low);
      if (!this->ImageFunction::IsInsideBuffer(low)) continue;
      image->TransformPhysicalPointToContinuousIndex(above, high);
      if (!this->ImageFunction::IsInsideBuffer(high)) continue;
      const double delta = above[dim] - below[dim];
      if (delta > 10.0 * std::numeric_limits<double>::epsilon()) {
        derivative[dim] =
          (linear->Interpolator::EvaluateAtContinuousIndex(high) - linear->Interpolator::EvaluateAtContinuousIndex(low)) / delta;
      }
    }
    return derivative;
  }

protected:
  MovingImageGradient() { this->UseImageDirectionOn(); }
  ~MovingImageGradient() override = default;

private:
  Interpolator::Pointer linear = Interpolator::New();
};

struct LevelMetric {
  Metric::Pointer metric;
  PointSet::Pointer points;
};

/// The metric of one level. The moving mask limits the samples and, as the metric initializes, the
/// moving image's histogram range, which it finds by asking the mask about every voxel (0.1 s at 1
/// mm); when the mask is known to keep the range whole (`maskKeepsRange`), it is given after that.
LevelMetric makeMetric(ScalarImage* fixed, ScalarImage* moving, PointSet* points, const MaskObject* mask, bool maskKeepsRange,
                       Transform* transform, unsigned bins)
{
  LevelMetric level;
  level.metric = Metric::New(); // DeterministicMattesMetric: a fixed split of the samples, summed in a fixed order
  level.points = points;
  level.metric->SetNumberOfHistogramBins(bins);
  level.metric->SetFixedImage(fixed);
  level.metric->SetMovingImage(moving);
  level.metric->SetMovingTransform(transform);
  level.metric->SetUseSampledPointSet(true);
  level.metric->SetFixedSampledPointSet(points);
  level.metric->SetUseMovingImageGradientFilter(false);
  level.metric->SetUseFixedImageGradientFilter(false);
  level.metric->SetMovingImageGradientCalculator(MovingImageGradient::New());
  if (mask && !maskKeepsRange) level.metric->SetMovingImageMask(mask);
  level.metric->Initialize();
  if (mask && maskKeepsRange) level.metric->SetMovingImageMask(mask);
  return level;
}

unsigned optimize(Metric* metric, double step, double minimumStep, unsigned iterations, CancelFlag cancel)
{
  auto scales = ScalesEstimator::New();
  scales->SetMetric(metric);
  scales->SetTransformForward(true);
  auto optimizer = Optimizer::New();
  optimizer->SetMetric(metric);
  optimizer->SetScalesEstimator(scales);
  optimizer->SetDoEstimateLearningRateOnce(false);
  optimizer->SetDoEstimateLearningRateAtEachIteration(false);
  optimizer->SetLearningRate(step);
  optimizer->SetMinimumStepLength(minimumStep);
  optimizer->SetRelaxationFactor(0.7);
  optimizer->SetGradientMagnitudeTolerance(1e-8);
  optimizer->SetNumberOfIterations(iterations);
  optimizer->SetReturnBestParametersAndValue(true);
  if (cancel) { // stop at the next iteration; the caller then throws
    auto observer = itk::CStyleCommand::New();
    observer->SetClientData(const_cast<std::atomic<bool>*>(cancel));
    observer->SetConstCallback([](const itk::Object* caller, const itk::EventObject&, void* flag) {
      if (static_cast<std::atomic<bool>*>(flag)->load()) {
        const_cast<Optimizer*>(static_cast<const Optimizer*>(caller))->StopOptimization();
      }
    });
    optimizer->AddObserver(itk::IterationEvent(), observer);
  }
  optimizer->StartOptimization();
  throwIfCancelled(cancel, "rigid registration");
  return optimizer->GetCurrentIteration();
}

/// The finest level's samples, on which the result's mutual information is judged: their points,
/// each one's bin of the fixed image (-1 outside it), and the moving image; the histograms span 0
/// to each image's maximum.
struct JudgedSamples {
  std::vector<PhysicalPoint> points;
  std::vector<int> fixedBins;
  const ScalarImage* moving = nullptr;
  double movingMax = 1;
  const MaskObject* mask = nullptr;
  unsigned bins = 32;
};

JudgedSamples judgedSamples(const ScalarImage& fixed, double fixedMax, const ScalarImage& moving, double movingMax,
                            const PointSet& points, const MaskObject* mask, unsigned bins)
{
  JudgedSamples s;
  s.moving = &moving;
  s.movingMax = movingMax;
  s.mask = mask;
  s.bins = bins;
  auto interpolator = Interpolator::New();
  interpolator->SetInputImage(&fixed);
  for (std::size_t i = 0, n = points.GetNumberOfPoints(); i < n; ++i) {
    const PhysicalPoint p = points.GetPoint(i);
    s.points.push_back(p);
    s.fixedBins.push_back(interpolator->IsInsideBuffer(p)
                            ? int(std::min(bins - 1, unsigned(std::max(0.0, interpolator->Evaluate(p) / fixedMax) * bins)))
                            : -1);
  }
  return s;
}

/// (H(F) + H(M)) / H(F, M) over the sampled points that land in the moving mask: the fixed image
/// at each point against the moving image where `toMoving` takes it.
double normalizedMutualInformation(const JudgedSamples& s, const std::function<PhysicalPoint(const PhysicalPoint&)>& toMoving,
                                   double& overlap)
{
  const unsigned bins = s.bins;
  auto movingInterpolator = Interpolator::New();
  movingInterpolator->SetInputImage(s.moving);
  std::vector<double> joint(bins * bins, 0.0), f(bins, 0.0), m(bins, 0.0);
  double total = 0;
  const std::size_t n = s.points.size();
  for (std::size_t i = 0; i < n; ++i) {
    if (s.fixedBins[i] < 0) continue;
    const PhysicalPoint q = toMoving(s.points[i]);
    if (!movingInterpolator->IsInsideBuffer(q)) continue;
    if (s.mask && !s.mask->IsInsideInWorldSpace(q)) continue;
    const unsigned a = unsigned(s.fixedBins[i]);
    const unsigned b = std::min(bins - 1, unsigned(std::max(0.0, movingInterpolator->Evaluate(q) / s.movingMax) * bins));
    joint[a * bins + b] += 1;
    total += 1;
  }
  overlap = n ? total / double(n) : 0.0;
  if (total == 0) return 1.0;
  double hJoint = 0, hF = 0, hM = 0;
  for (unsigned a = 0; a < bins; ++a) {
    for (unsigned b = 0; b < bins; ++b) {
      const double p = joint[a * bins + b] / total;
      f[a] += p;
      m[b] += p;
      if (p > 0) hJoint -= p * std::log(p);
    }
  }
  for (unsigned k = 0; k < bins; ++k) {
    if (f[k] > 0) hF -= f[k] * std::log(f[k]);
    if (m[k] > 0) hM -= m[k] * std::log(m[k]);
  }
  return hJoint > 0 ? (hF + hM) / hJoint : 1.0;
}

/// InputError when `image` cannot be registered at all: every voxel the same, or too small for
/// `minimumVoxels` voxels of the coarsest level (`coarsestMm`) along an axis.
void requireRegistrableImage(const ScalarImage& image, const std::string& which, double coarsestMm, unsigned minimumVoxels)
{
  const float* v = image.GetBufferPointer();
  const auto size = image.GetLargestPossibleRegion().GetSize();
  const std::size_t n = image.GetLargestPossibleRegion().GetNumberOfPixels();
  const auto range = std::minmax_element(v, v + n);
  if (n == 0 || *range.first == *range.second) {
    std::ostringstream why;
    why << "the " << which << " image is constant (every voxel " << (n ? *range.first : 0.0f)
        << "): no foreground or feature to register";
    throw InputError(why.str());
  }
  const double minimumMm = coarsestMm * minimumVoxels;
  for (unsigned i = 0; i < 3; ++i) {
    if (double(size[i]) * image.GetSpacing()[i] < minimumMm) {
      std::ostringstream why;
      why << "the " << which << " image is too small to register: " << size[0] << " x " << size[1] << " x " << size[2]
          << " voxels, " << double(size[i]) * image.GetSpacing()[i] << " mm along axis " << i << "; rigid registration needs "
          << minimumMm << " mm along each axis (" << minimumVoxels << " voxels of its coarsest " << coarsestMm << " mm level)";
      throw InputError(why.str());
    }
  }
}

/// InputError when the foreground of `image` (voxels above `threshold`) spans fewer than
/// `minimumVoxels` voxels along an axis: a speck, a line or a sheet gives no rotation to find.
void requireForegroundExtent(const ScalarImage& image, double threshold, const std::string& which, double levelMm,
                             unsigned minimumVoxels)
{
  const auto size = image.GetLargestPossibleRegion().GetSize();
  std::size_t low[3] = {size[0], size[1], size[2]}, high[3] = {0, 0, 0};
  const float* v = image.GetBufferPointer();
  std::size_t count = 0;
  for (std::size_t z = 0, i = 0; z < size[2]; ++z) {
    for (std::size_t y = 0; y < size[1]; ++y) {
      for (std::size_t x = 0; x < size[0]; ++x, ++i) {
        if (v[i] <= threshold) continue;
        const std::size_t at[3] = {x, y, z};
        for (int d = 0; d < 3; ++d) {
          low[d] = std::min(low[d], at[d]);
          high[d] = std::max(high[d], at[d]);
        }
        ++count;
      }
    }
  }
  if (count == 0) throw InputError("the " + which + " image has no foreground to register");
  for (int d = 0; d < 3; ++d) {
    if (high[d] - low[d] + 1 < minimumVoxels) {
      std::ostringstream why;
      why << "the " << which << " image's foreground is too small to register: it spans " << high[0] - low[0] + 1 << " x "
          << high[1] - low[1] + 1 << " x " << high[2] - low[2] + 1 << " voxels of the coarsest " << levelMm
          << " mm level (" << count << " voxels); rigid registration needs " << minimumVoxels << " along each axis";
      throw InputError(why.str());
    }
  }
}

/// InputError when every voxel of `image` above `threshold` has one value: mutual information has
/// no intensity range to bin (ITK's metric then fails with "A spacing of 0 is not allowed"). Checked
/// on every pyramid level: a uniform block keeps mixed values at its edges only when shrunk.
void requireVariedForeground(const ScalarImage& image, double threshold, const std::string& which)
{
  const float* v = image.GetBufferPointer();
  float lowest = std::numeric_limits<float>::max(), highest = std::numeric_limits<float>::lowest();
  for (std::size_t i = 0, n = image.GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) {
    if (v[i] <= threshold) continue;
    lowest = std::min(lowest, v[i]);
    highest = std::max(highest, v[i]);
  }
  if (lowest == highest) {
    std::ostringstream why;
    why << "the " << which << " image's foreground is uniform (every voxel above the background is " << lowest
        << "): no feature to register";
    throw InputError(why.str());
  }
}

void setRotationFromEuler(Transform& transform, double a, double b, double c)
{
  auto euler = itk::Euler3DTransform<double>::New();
  euler->SetRotation(a / Degrees, b / Degrees, c / Degrees);
  transform.SetMatrix(euler->GetMatrix());
}

double rotationAngleDegrees(const itk::Matrix<double, 3, 3>& r)
{
  const double trace = r(0, 0) + r(1, 1) + r(2, 2);
  return std::acos(std::clamp((trace - 1.0) / 2.0, -1.0, 1.0)) * Degrees;
}

} // namespace

void RigidRegistrationParameters::validate() const
{
  const std::size_t levels = levelSpacingMm.size();
  if (levels == 0 || samplesPerLevel.size() != levels || iterationsPerLevel.size() != levels ||
      stepMmPerLevel.size() != levels || minimumStepMmPerLevel.size() != levels) {
    throw InputError("rigid registration: every per-level setting needs one value per pyramid level");
  }
  for (std::size_t i = 0; i < levels; ++i) {
    if (!(levelSpacingMm[i] > 0) || samplesPerLevel[i] < 100 || !(stepMmPerLevel[i] > 0) ||
        !(minimumStepMmPerLevel[i] > 0)) {
      throw InputError("rigid registration: level " + std::to_string(i) +
                       " needs a positive spacing and step and at least 100 samples");
    }
  }
  if (histogramBins < 8 || histogramBins > 256) throw InputError("rigid registration: histogram bins must be 8 to 256");
  if (startAnglesDegrees.empty() || startsOptimized == 0) throw InputError("rigid registration: no start to try");
  if (!(baselineDisplacementMm > 0) || !(baselineDisplacementDegrees > 0) || !(minimumNormalizedMutualInformationGain >= 0)) {
    throw InputError("rigid registration: the displaced poses need a positive displacement and the gain a limit of at least 0");
  }
  if (minimumVoxelsPerAxis < 2 || minimumValidSamples < 10) {
    throw InputError("rigid registration: at least 2 voxels per axis and 10 valid samples are needed");
  }
}

double rotationDifferenceDegrees(const SpatialTransform& a, const SpatialTransform& b)
{
  const AffineParameters pa = affineParametersOf(&a), pb = affineParametersOf(&b);
  itk::Matrix<double, 3, 3> product; // A * B^T
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      double s = 0;
      for (int k = 0; k < 3; ++k) s += pa.matrix[r][k] * pb.matrix[c][k];
      product(r, c) = s;
    }
  }
  return rotationAngleDegrees(product);
}

class PreparedRigidMoving {
public:
  const ScalarImage* image = nullptr; ///< prepared from (identity, not ownership)
  const LabelImage* labels = nullptr;
  std::vector<double> levelSpacingMm;
  double maskDilationMm = 0;
  std::vector<ScalarImage::Pointer> levels; ///< coarsest first
  std::vector<double> maxima;               ///< of each level
  double threshold = 0;                     ///< foreground, from the coarsest level
  MaskObject::Pointer mask;                 ///< null without labels
  std::vector<bool> maskKeepsRange;         ///< of each level: maskKeepsIntensityRange
};

RigidRegistrationParameters rigidRegistrationParametersFrom(const Configuration& configuration)
{
  // The pyramid's first levels and a share of the samples (the configuration's speed knobs).
  RigidRegistrationParameters parameters;
  const std::size_t levels = std::min<std::size_t>(configuration.rigidLevels, parameters.levelSpacingMm.size());
  parameters.levelSpacingMm.resize(levels);
  parameters.iterationsPerLevel.resize(levels);
  parameters.stepMmPerLevel.resize(levels);
  parameters.minimumStepMmPerLevel.resize(levels);
  parameters.samplesPerLevel.resize(levels);
  for (unsigned& samples : parameters.samplesPerLevel) {
    samples = std::max(1000u, unsigned(std::lround(samples * configuration.rigidSamplingFraction)));
  }
  return parameters;
}

std::shared_ptr<const PreparedRigidMoving> prepareRigidMoving(const ScalarImage& preop, const LabelImage* preopLabels,
                                                              const RigidRegistrationParameters& parameters)
{
  parameters.validate();
  requireRegistrableImage(preop, "preoperative", parameters.levelSpacingMm.front(), parameters.minimumVoxelsPerAxis);
  auto prepared = std::make_shared<PreparedRigidMoving>();
  prepared->image = &preop;
  prepared->labels = preopLabels;
  prepared->levelSpacingMm = parameters.levelSpacingMm;
  prepared->maskDilationMm = parameters.maskDilationMm;
  for (double spacing : parameters.levelSpacingMm) {
    prepared->levels.push_back(shrinkTo(preop, spacing));
    prepared->maxima.push_back(maximumOf(*prepared->levels.back()));
  }
  prepared->threshold = foregroundThreshold(*prepared->levels.front());
  requireForegroundExtent(*prepared->levels.front(), prepared->threshold, "preoperative", parameters.levelSpacingMm.front(),
                          parameters.minimumVoxelsPerAxis);
  for (const ScalarImage::Pointer& level : prepared->levels) requireVariedForeground(*level, prepared->threshold, "preoperative");
  if (preopLabels) prepared->mask = movingMaskFrom(*preopLabels, parameters.maskDilationMm);
  for (const ScalarImage::Pointer& level : prepared->levels) {
    prepared->maskKeepsRange.push_back(prepared->mask && maskKeepsIntensityRange(*level, *prepared->mask));
  }
  return prepared;
}

namespace {
/// The preoperative side: as prepared by the caller (checked to be from these images and
/// settings), else prepared here.
std::shared_ptr<const PreparedRigidMoving> preparedMovingFor(const ScalarImage& preop, const LabelImage* preopLabels,
                                                             const RigidRegistrationParameters& parameters)
{
  std::shared_ptr<const PreparedRigidMoving> prepared = parameters.preparedMoving;
  if (!prepared) {
    prepared = prepareRigidMoving(preop, preopLabels, parameters);
  } else if (prepared->image != &preop || prepared->labels != preopLabels || prepared->levelSpacingMm != parameters.levelSpacingMm ||
             prepared->maskDilationMm != parameters.maskDilationMm) {
    throw std::invalid_argument("rigid registration: the preoperative side was prepared from other images or settings");
  }
  return prepared;
}

/// The intraoperative pyramid, coarsest first, and its foreground threshold; refuses an image too
/// small, with too little foreground or a flat one.
struct FixedPyramid {
  std::vector<ScalarImage::Pointer> levels;
  std::vector<double> maxima; ///< of each level
  double threshold = 0;
};

FixedPyramid fixedPyramidOf(const ScalarImage& intraop, const RigidRegistrationParameters& parameters)
{
  requireRegistrableImage(intraop, "intraoperative", parameters.levelSpacingMm.front(), parameters.minimumVoxelsPerAxis);
  FixedPyramid pyramid;
  for (double spacing : parameters.levelSpacingMm) {
    pyramid.levels.push_back(shrinkTo(intraop, spacing));
    pyramid.maxima.push_back(maximumOf(*pyramid.levels.back()));
  }
  pyramid.threshold = foregroundThreshold(*pyramid.levels.front());
  requireForegroundExtent(*pyramid.levels.front(), pyramid.threshold, "intraoperative", parameters.levelSpacingMm.front(),
                          parameters.minimumVoxelsPerAxis);
  for (const ScalarImage::Pointer& level : pyramid.levels) requireVariedForeground(*level, pyramid.threshold, "intraoperative");
  return pyramid;
}

/// The foreground centroids the start maps onto each other: the fixed one, and the moving one
/// measured over the part of the preoperative head that the intraoperative field of view covers.
struct ForegroundCentres {
  PhysicalPoint fixed, moving;
};

ForegroundCentres foregroundCentres(const FixedPyramid& fixed, const PreparedRigidMoving& moving)
{
  const ScalarImage& coarseFixed = *fixed.levels.front();
  ForegroundCentres centres;
  centres.fixed = centroidOfForeground(coarseFixed, fixed.threshold, nullptr);
  if (!std::isfinite(centres.fixed[0])) {
    throw InputError("the intraoperative image has no foreground to register");
  }
  centres.moving = centroidOfForeground(*moving.levels.front(), moving.threshold, nullptr);
  if (!std::isfinite(centres.moving[0])) throw InputError("the preoperative image has no foreground to register");
  for (int pass = 0; pass < 3; ++pass) {
    const itk::Vector<double, 3> shift = centres.moving - centres.fixed;
    const PhysicalPoint refined = centroidOfForeground(*moving.levels.front(), moving.threshold, [&](const PhysicalPoint& x) {
      itk::ContinuousIndex<double, 3> index;
      return coarseFixed.TransformPhysicalPointToContinuousIndex(x - shift, index);
    });
    if (!std::isfinite(refined[0])) break;
    centres.moving = refined;
  }
  return centres;
}

/// The starting transform about the fixed centre: the caller's initial transform, else the
/// translation between the centroids.
Transform::Pointer startingTransform(const ForegroundCentres& centres, const RigidRegistrationParameters& parameters)
{
  const PhysicalPoint& fixedCentre = centres.fixed;
  auto transform = Transform::New();
  transform->SetCenter(fixedCentre);
  if (parameters.initialIntraopToPreop) {
    const AffineParameters start = affineParametersOf(parameters.initialIntraopToPreop);
    Transform::MatrixType matrix;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) matrix(r, c) = start.matrix[r][c];
    }
    transform->SetMatrix(matrix);
    // y -> A y + t written about the centre: translation = A c + t - c.
    Transform::OutputVectorType translation;
    for (int r = 0; r < 3; ++r) {
      double s = start.translation[r] - fixedCentre[r];
      for (int c = 0; c < 3; ++c) s += start.matrix[r][c] * fixedCentre[c];
      translation[r] = s;
    }
    transform->SetTranslation(translation);
  } else {
    transform->SetTranslation(centres.moving - centres.fixed);
  }
  return transform;
}

struct ScoredStart {
  double value;
  std::array<double, 3> angles;
};

/// Every start rotation (the grid of start angles about the translation found) scored by the
/// metric, best first; those where fewer than a quarter of the samples land are left out.
std::vector<ScoredStart> scoredStarts(LevelMetric& metric, Transform& transform, const Transform::ParametersType& translationOnly,
                                      const RigidRegistrationParameters& parameters)
{
  std::vector<ScoredStart> starts;
  for (double a : parameters.startAnglesDegrees) {
    for (double b : parameters.startAnglesDegrees) {
      throwIfCancelled(parameters.cancel, "rigid registration");
      for (double c : parameters.startAnglesDegrees) {
        transform.SetParameters(translationOnly);
        setRotationFromEuler(transform, a, b, c);
        const double value = metric.metric->GetValue();
        if (metric.metric->GetNumberOfValidPoints() < metric.points->GetNumberOfPoints() / 4) continue;
        starts.push_back({value, {a, b, c}});
      }
    }
  }
  if (starts.empty()) {
    throw MethodError("rigid registration: no start overlaps the preoperative image; the images do not show the same anatomy");
  }
  std::sort(starts.begin(), starts.end(), [](const ScoredStart& x, const ScoredStart& y) { return x.value < y.value; });
  return starts;
}

/// The coarsest level without an initial transform: scores every start, optimizes the best few and
/// keeps the best end (left in `transform`); returns its iterations.
unsigned optimizeFromBestStarts(LevelMetric& metric, Transform& transform, const RigidRegistrationParameters& parameters,
                                RigidRegistrationResult& result)
{
  const Transform::ParametersType translationOnly = transform.GetParameters();
  const std::vector<ScoredStart> starts = scoredStarts(metric, transform, translationOnly, parameters);
  result.startsScored = unsigned(starts.size());
  double bestValue = std::numeric_limits<double>::max();
  Transform::ParametersType best;
  unsigned bestIterations = 0;
  for (std::size_t s = 0; s < std::min<std::size_t>(parameters.startsOptimized, starts.size()); ++s) {
    transform.SetParameters(translationOnly);
    setRotationFromEuler(transform, starts[s].angles[0], starts[s].angles[1], starts[s].angles[2]);
    const unsigned iterations = optimize(metric.metric, parameters.stepMmPerLevel[0], parameters.minimumStepMmPerLevel[0],
                                         parameters.iterationsPerLevel[0], parameters.cancel);
    const double value = metric.metric->GetValue();
    if (value < bestValue) {
      bestValue = value;
      best = transform.GetParameters();
      bestIterations = iterations;
      result.winningStartDegrees = starts[s].angles;
    }
  }
  transform.SetParameters(best);
  return bestIterations;
}

/// What the images share at poses known to be wrong, so that the trust does not rest on what one
/// contrast gives: the normalized mutual information of the same samples with the result displaced
/// by the baseline translation along, and rotation about, each axis through the transform's centre,
/// both ways (12 poses; those where fewer than minimumValidSamples land are left out). Their
/// highest and mean, and the result's gain over the highest: (NMI - 1) / (displaced - 1).
void measureDisplacedBaseline(const JudgedSamples& samples, const Transform& result, const RigidRegistrationParameters& parameters,
                              RigidRegistrationResult& out)
{
  // Poses 0 to 11: axis (pose / 4), way (pose / 2 % 2), translation or rotation (pose % 2); each
  // measured on its own (in parallel), gathered in order.
  std::array<double, 12> nmis{}, overlaps{};
  auto measure = [&](itk::SizeValueType pose) {
    const int axis = int(pose / 4);
    const double sign = (pose / 2) % 2 ? 1.0 : -1.0;
    auto displacement = itk::Euler3DTransform<double>::New();
    displacement->SetCenter(result.GetCenter());
    if (pose % 2) {
      double angles[3] = {0, 0, 0};
      angles[axis] = sign * parameters.baselineDisplacementDegrees / Degrees;
      displacement->SetRotation(angles[0], angles[1], angles[2]);
    } else {
      itk::Euler3DTransform<double>::OutputVectorType shift{};
      shift[axis] = sign * parameters.baselineDisplacementMm;
      displacement->SetTranslation(shift);
    }
    nmis[pose] = normalizedMutualInformation(
      samples, [&](const PhysicalPoint& p) { return result.TransformPoint(displacement->TransformPoint(p)); }, overlaps[pose]);
  };
  itk::MultiThreaderBase::New()->ParallelizeArray(0, itk::SizeValueType(nmis.size()), measure, nullptr);
  double highest = 1.0, sum = 0;
  unsigned compared = 0;
  for (std::size_t pose = 0; pose < nmis.size(); ++pose) {
    if (overlaps[pose] * double(samples.points.size()) < parameters.minimumValidSamples) continue;
    highest = std::max(highest, nmis[pose]);
    sum += nmis[pose];
    ++compared;
  }
  const double nan = std::numeric_limits<double>::quiet_NaN();
  out.displacedPosesCompared = compared;
  out.displacedNormalizedMutualInformation = compared ? highest : nan;
  out.displacedNormalizedMutualInformationMean = compared ? sum / compared : nan;
  // Both figures measure information above none (1); a baseline of exactly 1 shares nothing.
  out.normalizedMutualInformationGain =
    compared ? (out.normalizedMutualInformation - 1.0) / std::max(1e-6, highest - 1.0) : nan;
}

/// Each level of the pyramid, coarsest first, optimizes `transform` further; the finest level's
/// metric, valid samples, normalized mutual information and overlap go into `result`.
void optimizeOverPyramid(const FixedPyramid& fixed, const PreparedRigidMoving& moving, Transform* transform,
                         const RigidRegistrationParameters& parameters, RigidRegistrationResult& result)
{
  const std::size_t levels = parameters.levelSpacingMm.size();
  for (std::size_t level = 0; level < levels; ++level) {
    throwIfCancelled(parameters.cancel, "rigid registration");
    PointSet::Pointer points = sampleForeground(*fixed.levels[level], fixed.threshold, parameters.samplesPerLevel[level],
                                                parameters.seed + level);
    LevelMetric metric = makeMetric(fixed.levels[level], moving.levels[level], points, moving.mask, moving.maskKeepsRange[level],
                                    transform, parameters.histogramBins);
    if (level == 0 && !parameters.initialIntraopToPreop) {
      result.iterationsPerLevel.push_back(optimizeFromBestStarts(metric, *transform, parameters, result));
    } else {
      result.iterationsPerLevel.push_back(optimize(metric.metric, parameters.stepMmPerLevel[level],
                                                   parameters.minimumStepMmPerLevel[level],
                                                   parameters.iterationsPerLevel[level], parameters.cancel));
    }
    if (level + 1 == levels) {
      result.metricValue = metric.metric->GetValue();
      result.validSamples = unsigned(metric.metric->GetNumberOfValidPoints());
      result.metricWorkUnits = unsigned(metric.metric->derivativeWorkUnits());
      const JudgedSamples samples = judgedSamples(*fixed.levels[level], fixed.maxima[level], *moving.levels[level],
                                                  moving.maxima[level], *points, moving.mask, parameters.histogramBins);
      result.normalizedMutualInformation =
        normalizedMutualInformation(samples, [&](const PhysicalPoint& p) { return transform->TransformPoint(p); }, result.overlap);
      measureDisplacedBaseline(samples, *transform, parameters, result);
    }
  }
}

/// Can the result be trusted? The reason it cannot (empty when it can).
std::string untrustworthyBecause(const RigidRegistrationResult& result, const RigidRegistrationParameters& parameters)
{
  std::ostringstream why;
  if (result.validSamples < parameters.minimumValidSamples) {
    why << "only " << result.validSamples << " samples of the intraoperative foreground land on the preoperative image; "
        << "mutual information needs at least " << parameters.minimumValidSamples << " to be meaningful";
  } else if (result.overlap < parameters.minimumOverlap) {
    why << "only " << int(100 * result.overlap) << " % of the intraoperative foreground lands on the preoperative head";
  } else if (result.displacedPosesCompared == 0) {
    why << "no pose displaced by " << parameters.baselineDisplacementMm << " mm or " << parameters.baselineDisplacementDegrees
        << " degrees from the result keeps " << parameters.minimumValidSamples
        << " samples on the preoperative image, so its normalized mutual information " << result.normalizedMutualInformation
        << " cannot be told from a wrong pose's";
  } else if (!(result.normalizedMutualInformationGain >= parameters.minimumNormalizedMutualInformationGain)) {
    why << "normalized mutual information " << result.normalizedMutualInformation << " is only "
        << result.normalizedMutualInformationGain << " times as far above 1 as the "
        << result.displacedNormalizedMutualInformation << " of the best pose displaced by " << parameters.baselineDisplacementMm
        << " mm or " << parameters.baselineDisplacementDegrees << " degrees; an alignment of these images gives at least "
        << parameters.minimumNormalizedMutualInformationGain << " times";
  } else if (result.rotationDegrees > parameters.maximumRotationDegrees) {
    why << "a rotation of " << result.rotationDegrees << " degrees is implausible for a head in the scanner";
  }
  return why.str();
}

/// Warnings on a trusted result whose overlap, mutual information gain or rotation is near the limits.
void warnAboutDoubtfulAlignment(RigidRegistrationResult& result, const RigidRegistrationParameters& parameters)
{
  if (result.overlap < parameters.warningOverlap) {
    std::ostringstream w;
    w << "rigid: only " << int(100 * result.overlap) << " % of the intraoperative foreground overlaps the preoperative head";
    result.warnings.push_back(w.str());
  }
  if (result.normalizedMutualInformationGain < parameters.warningNormalizedMutualInformationGain) {
    std::ostringstream m;
    m << "rigid: normalized mutual information " << result.normalizedMutualInformation << " is only "
      << result.normalizedMutualInformationGain << " times as far above 1 as at the best displaced pose ("
      << result.displacedNormalizedMutualInformation << "); check the alignment";
    result.warnings.push_back(m.str());
  }
  if (result.rotationDegrees > parameters.warningRotationDegrees) {
    std::ostringstream r;
    r << "rigid: a large rotation (" << result.rotationDegrees << " degrees); check the alignment";
    result.warnings.push_back(r.str());
  }
}

RigidRegistrationResult registerRigidlyUnguarded(const ScalarImage& intraop, const ScalarImage& preop, const LabelImage* preopLabels,
                                                 const RigidRegistrationParameters& parameters)
{
  parameters.validate();
  RigidRegistrationResult result;
  // The pyramids, coarsest first; the preoperative side as prepared.
  const std::shared_ptr<const PreparedRigidMoving> moving = preparedMovingFor(preop, preopLabels, parameters);
  const FixedPyramid fixed = fixedPyramidOf(intraop, parameters);
  const ForegroundCentres centres = foregroundCentres(fixed, *moving);
  const Transform::Pointer transform = startingTransform(centres, parameters);
  optimizeOverPyramid(fixed, *moving, transform, parameters, result);

  result.intraopToPreop = transform.GetPointer();
  result.rotationDegrees = rotationAngleDegrees(transform->GetMatrix());
  result.translationMm = (transform->TransformPoint(centres.fixed) - centres.fixed).GetNorm();
  result.failureReason = untrustworthyBecause(result, parameters);
  result.trustworthy = result.failureReason.empty();
  if (result.trustworthy) warnAboutDoubtfulAlignment(result, parameters);
  return result;
}
} // namespace

RigidRegistrationResult registerRigidly(const ScalarImage& intraop, const ScalarImage& preop, const LabelImage* preopLabels,
                                        const RigidRegistrationParameters& parameters)
{
  try {
    return registerRigidlyUnguarded(intraop, preop, preopLabels, parameters);
  } catch (const itk::ExceptionObject& e) {
    // ITK's metric gives up on images it cannot measure (no sample inside the virtual domain, a
    // zero intensity range): a registration that failed, said in one line.
    throw MethodError("rigid registration failed on these images: " + oneLine(e.GetDescription()));
  }
}

} // namespace brainshift
