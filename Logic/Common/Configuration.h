#pragma once
// The run configuration (--config, JSON; ../shared/CONTRACT.md). Every key is optional; the
// defaults are Resources/Configurations/default.json's and the README's. Flags override the file.
#include <array>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace brainshift {

struct Material {
  double youngsModulusPa = 3000.0;
  double poissonRatio = 0.45;
};

struct Configuration {
  /// Per label. Defaults: brain parenchyma 3000 Pa / 0.45 (Warfield et al. 2000), ventricles soft
  /// (100 Pa / 0.3: CSF carries almost no shear), tumour stiffer (10 kPa / 0.45).
  std::map<int, Material> materials{{2, {3000.0, 0.45}}, {3, {100.0, 0.3}}, {4, {10000.0, 0.45}}};
  /// 4 mm: as accurate as 3 mm on the built-in case (landmark TRE 0.73 against 0.74 mm) in two thirds of
  /// the time, without the tissue losses of coarser lattices (Testing/Benchmarks/results/update).
  double meshResolutionMm = 4.0;
  std::vector<int> meshLabels{2, 3, 4};
  std::string meshBackend = "lattice"; ///< "lattice" or "cgal" (CGAL Mesh_3)
  /// Graded lattice: element size grows by this many mm per mm of distance from the tissue
  /// interfaces, the brain's surface and the region of interest (0: uniform), up to
  /// 2^meshCoarseningLevels times the resolution.
  double meshGrading = 0.0;
  int meshCoarseningLevels = 2;
  /// A sphere meshed at the resolution throughout: LPS centre and radius, mm (radius 0: none).
  std::array<double, 3> meshRegionOfInterestCenterLps{};
  double meshRegionOfInterestRadiusMm = 0.0;
  std::string solverOptions; ///< PETSc options over the tuned default
  /// 2: on this 2-core machine the default problem (95,610 equations) solves in 0.29-0.30 s on two
  /// ranks against 0.55-0.71 s on one, the whole simulate stage in 1.1-1.2 s against 1.5-1.8 s.
  int ranks = 2;
  /// Rigid registration: the share of the metric's samples at every level (1: 12,000, 30,000 and
  /// 60,000 from the coarsest) and how many levels of the pyramid (4, 2, 1 mm) are run, coarsest
  /// first (Testing/Benchmarks/results/update measures both).
  double rigidSamplingFraction = 1.0;
  unsigned rigidLevels = 3;
  /// Tissue classification: k of the k-NN, saturation of the spatial channels, N4 on or off.
  unsigned classificationK = 7;
  double classificationSaturationMm = 10.0;
  bool classificationBiasCorrection = false;
  /// The prototypes: how many a tissue, and the seed of their choice among the candidates (the
  /// same seed, the same prototypes and labels; another seed is another draw of the same rule, the
  /// way to measure what one draw is worth: README, "Tissue classification").
  unsigned classificationPrototypesPerTissue = 150;
  unsigned classificationSeed = 2000;
  /// Thick fluid in the brain (a gap, a cavity) measured over the aligned preoperative brain too.
  bool classificationFluidThicknessInAlignedBrain = true;
  /// A tumour in place: its k-NN voxels that look more like fluid than its own look may be fluid.
  bool classificationTumourFluidByLook = true;
  /// "auto" (decided from the image where the aligned tumour lies), "yes" or "no".
  std::string classificationTumourResected = "auto";
  /// The tumour decided by the image is looked at again where the first solve put it (the refine
  /// stage, whatever its passes): decided otherwise there (resectionShownWhereSolved for one kept in
  /// place, tumourShownInPlaceWhereSolved for one found resected), the scan is classified, fitted
  /// and solved once more. False: the first decision stands.
  bool classificationTumourSecondLook = true;
  /// Passes of the classification that follows the brain (Warfield et al.'s adaptive template):
  /// after a solve the preoperative labels warped by it become the spatial prior, and the
  /// classification, the surface and the solve run again, at most this many times more, until the
  /// imposed surface displacement changes by less than the tolerance (mean over its nodes). (Before
  /// them, and with none, the tumour's second look may run one pass: classificationTumourSecondLook.)
  /// Empty: "auto", one pass where the scan's fluid is brighter than its parenchyma (T2-like: the
  /// classification's own rule for the gap under the craniotomy measures fluid thickness over the
  /// aligned preoperative brain only in T1-like scans, and the warped prior takes its place), none
  /// elsewhere.
  std::optional<unsigned> classificationRefinementPasses;
  double classificationRefinementToleranceMm = 0.25;
  /// A refine pass reclassifies only within this distance of where the solve moved the tissue by
  /// more than 1 mm, and keeps the first classification elsewhere (0: everywhere).
  double classificationRefinementReachMm = 20.0;
  /// Active surface: elastic weights of the displacement (membrane, bending), the image term's
  /// share, the iteration limit.
  double surfaceMembraneWeight = 1.0;
  double surfaceBendingWeight = 0.2;
  double surfaceImageWeight = 0.0;
  unsigned surfaceMaximumIterations = 200;
  /// Nodes that moved matched along the brain's common sinking direction, not to the closest point;
  /// matched nodes put on the boundary at the end; the membrane's residual, filtered once more,
  /// added (ActiveSurfaceLogic.h).
  bool surfaceMatchAlongSinkingDirection = true;
  bool surfaceSnapToBoundary = false;
  bool surfaceResidualCorrection = true;
  /// Surface nodes outside the intraoperative field of view: held at rest (true) or left free.
  bool surfaceHoldOutsideFieldOfView = true;
  /// Imposed surface nodes whose surface moved less than this (mm) about them held at rest, ramped
  /// up to all of their move at twice it; the local move is the displacement filtered by the membrane
  /// this many times (ActiveSurfaceParameters::restBandMm, restBandSmoothingPasses; 0 mm: off).
  double surfaceRestBandMm = 1.0;
  unsigned surfaceRestBandSmoothingPasses = 4;
  /// Block matching inside the brain (Logic/BlockMatching) and its matches as soft constraints of
  /// the solve, rejected in rounds (FiniteElementJob.h): "block_matching" in the file.
  struct BlockMatching {
    bool enabled = true;
    /// Chosen on Testing/Benchmarks/results/blockmatching and five hard scenarios (README): 3,000
    /// blocks 4 mm apart, stiffer matches (0.01 -> 0.03 -> 0.1 -> 0.3 N/mm, each better on the mean
    /// of the five) and a rejection of gross outliers only (2 mm, 3.5 robust sigmas). The blocks
    /// spread over 8 mm cubes (of 0, 8, 12 and 16 the best on all 26 hard scenarios, README "Blocks
    /// spread over the brain").
    double blockHalfSizeMm = 4.0, blockSpacingMm = 4.0, selectedShare = 0.5, searchRadiusMm = 6.0, minimumSimilarity = 0.5;
    double maximumBlocks = 3000;
    double selectionCellMm = 8;     ///< the selection spread over cubes this wide (BlockMatching.h); 0: by structure alone
    /// Where the surface-driven solve shears or stretches the brain, each block matched in the
    /// window it deforms too, the better correlation kept (BlockMatchingParameters::deformedWindows;
    /// README "Blocks matched as the brain deforms": better on the hard scenarios' large sinks).
    bool deformedWindows = true;
    /// Both images smoothed by a Gaussian of this sigma (mm) before blocks are matched
    /// (BlockMatchingParameters::smoothingMm), and the matches, less noisy, held stiffer (0.3 -> 1
    /// N/mm): README "Blocks matched in smoothed images" (both together better on the hard
    /// scenarios, each alone not).
    double smoothingMm = 0.7;
    double stiffnessNPerMm = 1.0;   ///< of a match of correlation 1 along the directions its structure pins down
    double rejectionRounds = 3, rejectionFraction = 0.1, outlierFactor = 3.5, rejectionFloorMm = 2.0;
  } blockMatching;
  /// The confidence map's model (DisplacementUncertainty.h): "uncertainty" in the file. No growth
  /// with the distance from the evidence and a quarter of the displacement: chosen on the 24
  /// scenarios (README, "The confidence map").
  struct Uncertainty {
    double floorMm = 0.3, growthPerMm = 0.0, misfitReachMm = 8.0, displacementShare = 0.25;
  } uncertainty;

  /// Reads `path` over the defaults. InputError naming the file and the key for malformed JSON,
  /// unknown keys, a Poisson ratio outside [0, 0.49) (0.49 and above lock linear tetrahedra), a
  /// Young's modulus outside 1 Pa to 1e9 Pa, and the like.
  static Configuration load(const std::filesystem::path& path);
  /// load(path), or the defaults for an empty path.
  static Configuration loadOrDefaults(const std::filesystem::path& path) { return path.empty() ? Configuration{} : load(path); }

  /// Checks the values; `source` names where they came from in the error message.
  void validate(const std::string& source) const;
  void validateBlockMatching(const std::string& source) const;
  void validateUncertainty(const std::string& source) const;
};

} // namespace brainshift
