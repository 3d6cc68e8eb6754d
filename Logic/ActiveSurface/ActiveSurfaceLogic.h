#pragma once
// Surface correspondence (Warfield et al. 2000, after Ferrant et al.): an active surface carries
// the preoperative brain surface onto the intraoperative brain boundary, and its displacements
// become the boundary conditions of the volumetric solve.
//
// The surface is the brain boundary of the tetrahedral mesh (its nodes keep their mesh node ids).
// It lives in the model frame (the preoperative frame); the intraoperative data are reached
// through the rigid transform. What moves it:
// - the external force pulls each node along the gradient of a smoothed signed distance map of the
//   intraoperative brain (cavity and holes filled, the largest component kept) towards its zero
//   level, capped per iteration;
// - an image term guards that target with the intraoperative intensity: the expected grey levels
//   just inside and just outside the brain are learned from the segmentation's own boundary band;
//   where the segmentation's boundary does not show their contrast locally (a few mm inside against
//   a few mm outside), the segmentation is wrong there and the node follows the image's edge
//   instead (the crossing between the two grey levels along its normal), so a classification error does not
//   drag the surface. Where the segmentation looks right, the edge may also refine it
//   (`imageWeight`; off by default, as measured);
// - internal elastic forces act on the displacement from a rest shape (not on the positions, so the
//   surface does not shrink): a membrane (graph Laplacian K) and a bending term (K^2), stepped
//   semi-implicitly, v <- (I + tau (alpha K + beta K^2))^-1 (v + tau f(rest + v)), the matrix
//   factorised once (as (I + a K)(I + c K) when it can be). The rest shape is the preoperative
//   boundary itself: the same active surface first carries the mesh's surface (Taubin-smoothed)
//   onto the preoperative labels' boundary, and the displacement imposed on each node is the move
//   from there to the intraoperative boundary; so the lattice's staircase and the method's own
//   smoothing cancel out, and no shift means no motion.
// Iteration stops when 95 % of the nodes move less than `convergenceMm` in a step (or, after 30
// steps, when the mean movement has stayed below half of it for five).
//
// Nodes without a counterpart are left free (Imposed 0) for the solve rather than imposed wrongly:
// nodes of a tumour that has been resected (its surface has become a cavity's wall), nodes whose
// intraoperative position falls outside the intraoperative image (a slab field of view; or held at
// rest, `holdOutsideFieldOfView`), and nodes that end farther than `unmatchedResidualMm` from the
// target boundary.
#include "BrainShiftErrors.h"
#include "ImageTypes.h"
#include "TransformIO.h"

#include <vtkPolyData.h>
#include <vtkSmartPointer.h>
#include <vtkUnstructuredGrid.h>

#include <array>
#include <string>
#include <vector>

namespace brainshift {

struct ActiveSurfaceParameters {
  CancelFlag cancel = nullptr;       ///< polled at every iteration: CancelledError when set
  double membraneWeight = 1.0;       ///< alpha: resistance to stretching of the displacement
  double bendingWeight = 0.2;        ///< beta: resistance to bending (alpha^2 >= 4 beta / tau: fast path)
  double timeStep = 1.0;             ///< tau of the semi-implicit step
  double maximumStepMm = 2.0;        ///< the external force's pull per iteration is capped here
  unsigned maximumIterations = 200;
  unsigned restSmoothingIterations = 10; ///< Taubin passes that take the staircase off the rest shape
  double convergenceMm = 0.02;       ///< 95th percentile of the node movements in a step: converged
  double distanceSmoothingMm = 1.0;  ///< Gaussian sigma on the distance map (removes staircasing)
  /// Share of the image's edge in the target where the segmentation looks right (0: the
  /// segmentation alone there; measured best on the built-in case, Testing/Benchmarks/surface).
  double imageWeight = 0.0;
  /// Where the expected grey levels say the segmentation is wrong, the image's edge alone moves the node.
  bool imageRescue = true;
  /// The segmentation looks right at a node when the intensity 1-4 mm inside and 1-4 mm outside
  /// its boundary differ by at least this share of the expected contrast.
  double minimumContrastFraction = 0.35;
  /// The brain's surroundings are two-sided (darker and brighter than the brain: T2's bright fluid
  /// beside dark bone and air) when the segmentation's fluid (`fluidLabel`) is brighter than its
  /// parenchyma and at least this share of the band outside the segmentation's boundary lies on
  /// each side of the band inside; else one-sided (T1, FLAIR, low field), as it always was.
  double twoSidedMinimumShare = 0.1;
  int fluidLabel = 3, parenchymaLabel = 2;
  double imageSearchMm = 3.0;        ///< the image term looks this far along the normal, both ways
  double imageTrustMm = 1.5;         ///< and is used only where it agrees with the segmentation this well
  double unmatchedResidualMm = 2.0;  ///< a node ending farther than this from the target is left free
  double resectedFraction = 0.25;    ///< tumour volume left in the intraop labels below this: resected
  /// Match the nodes that moved along the brain's common sinking direction instead of to the
  /// closest point (matchAlongSinkingDirection in the .cxx): the closest point loses the motion's
  /// tangential part.
  bool matchAlongSinkingDirection = true;
  double sinkingNodeMm = 2.0;          ///< nodes moved farther than this by the closest-point fit estimate the direction
  std::size_t sinkingMinimumNodes = 20; ///< fewer such nodes: no common sinking, closest points only
  double sinkingCoherence = 0.5;       ///< |sum of their moves| / sum of |moves| below this: no common direction
  double directionalNodeMm = 0.5;      ///< nodes moved farther than this are matched along the direction
  double directionalMinimumCosine = 0.35; ///< and only where their normal is this close to it
  double directionalSearchMm = 10.0;   ///< how far the line's crossing may lie from the closest-point fit's
  /// Put each matched node on the boundary at the end (snapOntoBoundary in the .cxx) rather than
  /// where the membrane's equilibrium leaves it, short of the boundary.
  bool snapToBoundary = false;
  /// Add the membrane's residual, filtered by the membrane once more (twicing; correctMembraneResidual
  /// in the .cxx): the smooth part of what the equilibrium leaves short of the target, the bottom
  /// of a deep sink, is taken up; the boundary's roughness stays filtered. On: chosen on the
  /// scenarios' finite element truths (README, "Active surface").
  bool residualCorrection = true;
  /// The segmentation's offset at the brain boundary (measureSegmentationOffset in the .cxx): the
  /// median move of the nodes it placed along their outward normal. Over a surface most of which
  /// did not move it is where this scan's classification puts the brain's edge against where the
  /// preoperative labels put it, and the solve carries it into the brain beneath the whole surface.
  /// Beyond this (mm, either way), or beyond `boundaryOffsetWarningVoxels` of the scan's voxel
  /// (the cube root of its volume) if that is more, a warning says so: a segmentation on a voxel
  /// grid places its boundary within a fraction of a voxel by partial volume alone (the small
  /// built-in case, 2.5 x 2.5 x 5 mm voxels, T1: 0.83 mm inside with its deep brain better than
  /// rigid; its T2 scan 1.78 mm inside and its deep brain 1.06 mm off against rigid's 0.39).
  double boundaryOffsetWarningMm = 0.5;
  double boundaryOffsetWarningVoxels = 1.0 / 3.0;
  /// Measured only when the nodes the segmentation placed cover at least this share of the surface
  /// (a slab's view may be mostly the region that moved).
  double boundaryOffsetMinimumShare = 0.6;
  /// The rest band (holdAtRest in the .cxx): an imposed node where the surface moved less than this
  /// (mm) is held at rest, and between it and twice it the node's move is scaled from nothing to
  /// all of it, so the imposed field stays continuous. Most of the brain surface lies against the
  /// skull and did not move; there the segmentation's boundary noise (about 0.7 mm on T1, 1.4 mm on
  /// T2 on the scenarios, where the truth moved less than 0.5 mm) is all the surface measures, and the
  /// solve carries it into the brain beneath. 0: off, every move imposed as found. Chosen on the 24
  /// scenarios (README, "Active surface").
  double restBandMm = 1.0;
  /// The band is judged on the surface's local mean move, the displacement filtered by the membrane
  /// this many times (0: each node's own move).
  unsigned restBandSmoothingPasses = 4;
  /// A partial field of view (a slab around the craniotomy): the surface nodes it does not cover
  /// are left free for the elastic model (false), or held at rest where the skull holds them (true:
  /// imposed, zero displacement).
  bool holdOutsideFieldOfView = true;
  /// Too little of the brain seen to say anything: fewer surface nodes than this share, or less
  /// brain than this volume, inside the intraoperative field of view (InputError naming both).
  double minimumCoveredSurfaceShare = 0.15;
  double minimumCoveredBrainMl = 100.0;
  std::vector<int> brainLabels{2, 3, 4}; ///< the mesh tissues whose union is the brain
  int tumourLabel = 4;
  void validate() const;
};

struct ActiveSurfaceResult {
  /// The deformed brain surface (model frame, LPS mm): point arrays "Displacement",
  /// "DisplacementMagnitude", "MeshNodeId", "Imposed" (as ../shared/CONTRACT.md says).
  vtkSmartPointer<vtkPolyData> surface;
  unsigned iterations = 0;
  bool converged = false;
  std::size_t surfaceNodes = 0, imposedNodes = 0;
  std::size_t freeResected = 0, freeOutsideImage = 0, freeUnmatched = 0;
  std::size_t heldOutsideImage = 0; ///< outside the field of view, held at rest (holdOutsideFieldOfView)
  /// What the intraoperative field of view covers after the rigid transform: surface nodes, and
  /// the meshed brain's volume (tetrahedra whose centroid it holds) against the whole.
  std::size_t coveredSurfaceNodes = 0;
  double coveredBrainMl = 0, meshedBrainMl = 0;
  bool tumourResected = false;
  /// Distance of the imposed nodes to the target boundary at the end (mm).
  double meanResidualMm = 0, p95ResidualMm = 0, maxResidualMm = 0;
  double initialMeanResidualMm = 0;  ///< the same before deforming
  double meanDisplacementMm = 0, maxDisplacementMm = 0;
  double expectedInsideIntensity = 0, expectedOutsideIntensity = 0;
  double outsideBrighterShare = 0;   ///< of the band outside the boundary, the share brighter than the inside median
  bool fluidBrighterThanParenchyma = false; ///< the segmentation's fluid against its parenchyma, in the image
  std::size_t outsideSides = 0;      ///< 1: surroundings on one side of the brain's intensity, 2: both (T2), 0: no image term
  std::size_t imageTermNodes = 0;    ///< nodes where the image term found an edge at the end
  std::size_t flippedTriangles = 0;  ///< triangles whose orientation reversed (should be none)
  std::array<double, 3> sinkingDirection{}; ///< the common direction estimated (model frame; 0: none)
  std::size_t directionalNodes = 0;  ///< nodes matched along it
  std::size_t unsnappedNodes = 0;    ///< nodes kept at the membrane's position (snapping would turn a triangle over)
  /// The rest band (restBandMm): imposed nodes held at rest, and those whose move it scaled down.
  std::size_t restHeldNodes = 0, restScaledNodes = 0;
  /// The median of the local mean move it judged, over the matched nodes (mm; 0: band off).
  double restLocalMoveMedianMm = 0;
  /// The residual correction (residualCorrection): its mean length over the matched nodes and its largest (mm).
  double residualCorrectionMeanMm = 0, residualCorrectionMaxMm = 0;
  /// The segmentation's offset at the brain boundary (boundaryOffsetWarningMm): the median move of
  /// the nodes it placed along the outward normal (mm; negative: inside the preoperative boundary)
  /// and over how many nodes (0: not measured).
  double boundaryOffsetMm = 0;
  std::size_t boundaryOffsetNodes = 0;
  double boundaryOffsetWarningMm = 0; ///< the offset warned of beyond this, on this scan's voxels (mm)
  /// The fit to the preoperative boundary (mesh and preoperative labels only: could be prepared
  /// before surgery), the intraoperative target's distance map, the intraoperative iterations.
  double preopBoundarySeconds = 0, targetSeconds = 0, iterationSeconds = 0;
  Warnings warnings;
};

/// The names the errors use for the inputs (their files, where they came from files).
struct ActiveSurfaceInputNames {
  std::string mesh = "the mesh";
  std::string preopLabels = "the preoperative labels";
  std::string labels = "the intraoperative segmentation";
  std::string rigid = "the rigid transform";
  std::string previousSurface = "the previous scan's surface";
};

/// Deforms the brain boundary of `mesh` (cell array "Label") onto the brain of `intraopLabels`.
/// `preopLabels` (the label map the mesh was made from) tells where the preoperative boundary is
/// at each node: the displacement is the move from there to the intraoperative boundary. Without
/// it the mesh's own (smoothed) surface stands for the preoperative boundary.
/// `intraopImage` (same grid as the labels) feeds the image term; null turns it off.
/// InputError for a mesh without the brain labels or with a non-manifold brain surface, an empty
/// target segmentation, an intraoperative field of view that covers too little of the brain (the
/// shares in the message), mismatched grids.
/// MethodError if the surface folds (triangles reversed) or most nodes find no counterpart.
/// The result's surface carries the preoperative boundary it found as the point array
/// "PreopBoundary" (model frame, mm). `previousSurface`, an earlier scan's result on the same mesh
/// and preoperative labels, gives it back: the preoperative fit is skipped (the serial scan's
/// saving); a surface of another mesh (other node ids or count) is an InputError naming
/// `names.previousSurface`.
struct Configuration;
/// The surface stage's parameters from the one configuration (the elastic and image weights, the
/// iterations, the matching along the sinking direction, snapping, the field of view's hold): what
/// the command line and the Surface and simulation panel start from.
ActiveSurfaceParameters activeSurfaceParametersFrom(const Configuration& configuration);

ActiveSurfaceResult deformBrainSurface(vtkUnstructuredGrid* mesh, const LabelImage* preopLabels, const LabelImage& intraopLabels,
                                       const ScalarImage* intraopImage, const SpatialTransform& rigidIntraopToPreop,
                                       const ActiveSurfaceParameters& parameters,
                                       const ActiveSurfaceInputNames& names = {}, vtkPolyData* previousSurface = nullptr);

/// The brain surface of `mesh` at the preoperative brain boundary, found on the preoperative labels
/// as deformBrainSurface finds it (its first step, and the most costly): a surface without
/// displacement (every node "Imposed" at rest) whose "PreopBoundary" deformBrainSurface takes as
/// its `previousSurface` instead of fitting again. It needs the preoperative data alone, so it can
/// be made while the scan is still registered and classified. The same inputs errors as
/// deformBrainSurface's.
struct PreoperativeBrainBoundary {
  vtkSmartPointer<vtkPolyData> surface;
  double seconds = 0;
  Warnings warnings; ///< the fit did not converge
};
PreoperativeBrainBoundary preoperativeBrainBoundary(vtkUnstructuredGrid* mesh, const LabelImage& preopLabels,
                                                    const ActiveSurfaceParameters& parameters, const ActiveSurfaceInputNames& names = {});

} // namespace brainshift
