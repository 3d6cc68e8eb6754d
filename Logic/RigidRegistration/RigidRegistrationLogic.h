#pragma once
// Rigid registration of the intraoperative MRI (fixed) to the preoperative MRI (moving) by
// Mattes mutual information (ITK v4 metric and optimizer), over a three-level pyramid, from a
// start that does not depend on luck: the foreground centroids (corrected for the
// intraoperative field of view) and a multi-start over rotations at the coarsest level. The
// result is the contract's `rigid_intraop_to_preop`: it maps an intraoperative point to the
// preoperative point it shows. Sampling is seeded: same inputs, same transform.
#include "BrainShiftErrors.h"
#include "ImageTypes.h"
#include "TransformIO.h"

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace brainshift {

class PreparedRigidMoving;

struct RigidRegistrationParameters {
  /// Voxel size of each pyramid level, coarsest first, in mm: each image is bin-shrunk (averaged)
  /// by the whole factor per axis that comes closest without going below its own spacing.
  std::vector<double> levelSpacingMm{4.0, 2.0, 1.0};
  /// The finest level's samples make the mutual information's landscape the optimizer stops in:
  /// with 60,000 the rf10-t1post scenario's stopped 0.57 mm from the true pose (head landmarks; 0.12
  /// with 90,000, 120,000, other seeds or bins); over the 26 scenarios, 90,000 gave head landmarks
  /// 0.155 mm mean, 0.31 at most, against 0.171 and 0.57 (rigid alone; Testing/Benchmarks/results/rigid/samples.md).
  std::vector<unsigned> samplesPerLevel{12000, 30000, 90000};
  std::vector<unsigned> iterationsPerLevel{100, 80, 50};
  std::vector<double> stepMmPerLevel{3.0, 1.0, 0.5};     ///< first step of the optimizer
  std::vector<double> minimumStepMmPerLevel{0.05, 0.02, 0.01};
  unsigned histogramBins = 32;
  /// Multi-start: Euler angles (degrees) tried about each axis; every combination is scored at
  /// the coarsest level and the best `startsOptimized` are optimized there.
  std::vector<double> startAnglesDegrees{-40.0, -20.0, 0.0, 20.0, 40.0};
  unsigned startsOptimized = 4;
  /// The preoperative labels (head and brain, dilated by this much) limit the metric.
  double maskDilationMm = 8.0;
  std::uint64_t seed = 2000;
  /// Polled at every optimizer iteration and start: CancelledError when set.
  CancelFlag cancel = nullptr;
  /// The preoperative side prepared once (prepareRigidMoving) from the very images given to
  /// registerRigidly, with the same levels and mask dilation (else std::invalid_argument); null:
  /// prepared there.
  std::shared_ptr<const PreparedRigidMoving> preparedMoving;
  /// A known start (for example the previous scan's result): used instead of the multi-start.
  SpatialTransform::ConstPointer initialIntraopToPreop;

  // When the result cannot be trusted (exit 1) and when it only deserves a warning.
  double minimumOverlap = 0.5, warningOverlap = 0.8;
  /// The normalized mutual information (NMI) at the result is compared with that of the same
  /// samples at 12 poses displaced from it by this much along and about each axis: what these very
  /// images share at a wrong pose, whatever their contrasts.
  double baselineDisplacementMm = 15.0, baselineDisplacementDegrees = 15.0;
  // The gain (NMI - 1) / (displaced NMI - 1). Calibrated (Testing/Benchmarks/results/rigid/contrast.md)
  // on every built-in scenario, T1, low-field T1, T2, FLAIR, T1 post-contrast and slabs: right
  // alignments give 3.8 to 5.9 on the small case and 5.6 to 9.5 at full size; gross failures
  // (upside down, turned round) and unrelated images 0.98 to 1.3, poses 5 to 20 degrees off 0.3 to
  // 1.7. Poses 2 to 7 mm off that the finest level left half recovered still gave 2.6 to 4.9: this
  // figure, like the NMI before it, catches wrong optima and gross failures, not millimetres. (The
  // NMI itself is 1.10 to 1.33 at right alignments, 1.10 for FLAIR and 1.14 for T2 on the small case,
  // so no absolute floor serves every contrast.)
  double minimumNormalizedMutualInformationGain = 2.5, warningNormalizedMutualInformationGain = 3.3;
  double warningRotationDegrees = 45.0, maximumRotationDegrees = 90.0;
  /// Too little to register (InputError): each image, and the intraoperative foreground, must span
  /// this many voxels of the coarsest level along every axis.
  unsigned minimumVoxelsPerAxis = 4;
  /// Too few samples for mutual information to mean anything (untrustworthy): the finest level's
  /// samples that land inside the preoperative image (and mask) at the result.
  unsigned minimumValidSamples = 500;

  void validate() const; ///< InputError for inconsistent or absurd values
};

struct RigidRegistrationResult {
  SpatialTransform::Pointer intraopToPreop; ///< an itk::VersorRigid3DTransform
  double metricValue = 0;                   ///< Mattes MI at the finest level (negative: better)
  unsigned validSamples = 0;                ///< of the finest level's samples, those the metric used at the result
  double normalizedMutualInformation = 0;   ///< (H(F) + H(M)) / H(F, M) on the finest samples, 1..2
  double overlap = 0;                       ///< fraction of fixed samples landing in the moving mask
  /// The NMI of the same samples at the displaced poses (baselineDisplacementMm and -Degrees): the
  /// highest and the mean of those compared (NaN when none keeps minimumValidSamples).
  double displacedNormalizedMutualInformation = 0, displacedNormalizedMutualInformationMean = 0;
  unsigned displacedPosesCompared = 0;
  /// (NMI - 1) / (displaced NMI - 1): how many times more the images share at the result than at
  /// the best wrong pose; the trust reads this, not the NMI.
  double normalizedMutualInformationGain = 0;
  double rotationDegrees = 0, translationMm = 0; ///< of the result, about the fixed foreground centre
  std::vector<unsigned> iterationsPerLevel;
  /// The work units the finest level's metric split its samples over: a fixed four (on as many
  /// threads as there are cores), summed in a fixed order, so the transform does not depend on the
  /// machine or the threads' timing.
  unsigned metricWorkUnits = 0;
  std::array<double, 3> winningStartDegrees{}; ///< the multi-start's winning Euler angles
  unsigned startsScored = 0;
  bool trustworthy = true;
  std::string failureReason; ///< why not, when not
  Warnings warnings;
};

struct Configuration;
/// The rigid stage's parameters from the one configuration (the pyramid's levels, the share of the
/// metric's samples): what the command line and the Rigid registration panel start from.
RigidRegistrationParameters rigidRegistrationParametersFrom(const Configuration& configuration);

/// The preoperative side of the registration, the same for every scan of a case: the moving
/// image's pyramid, its foreground threshold and the metric's mask from the labels (`labels` may be
/// null). A session (brainshift watch) prepares it once.
std::shared_ptr<const PreparedRigidMoving> prepareRigidMoving(const ScalarImage& preop, const LabelImage* preopLabels,
                                                              const RigidRegistrationParameters& parameters);

/// Registers; the images may be anisotropic and on different grids. InputError for an image that
/// is constant, smaller than minimumVoxelsPerAxis coarsest voxels along an axis, or without a
/// foreground that spans as much; the result says whether it can be trusted (too few valid samples,
/// little overlap, normalized mutual information little above that of displaced poses, an
/// implausible rotation).
RigidRegistrationResult registerRigidly(const ScalarImage& intraop, const ScalarImage& preop,
                                        const LabelImage* preopLabels, const RigidRegistrationParameters& parameters);

/// The angle (degrees) of the rotation that takes `a`'s rotation to `b`'s, and the distance
/// between their images of `point`: how far apart two rigid transforms are.
double rotationDifferenceDegrees(const SpatialTransform& a, const SpatialTransform& b);

} // namespace brainshift
