#pragma once
// Accuracy of the brain surface's displacements (the active surface's output) against a known
// deformation: the simulated case's truth.
#include "ImageTypes.h"
#include "TransformIO.h"

#include <vtkPolyData.h>

#include <array>
#include <memory>
#include <set>

namespace brainshift {

struct SurfaceDisplacementAccuracy {
  std::size_t nodes = 0;  ///< imposed nodes evaluated
  /// |estimated - true displacement| over the imposed nodes (mm).
  double meanErrorMm = 0, medianErrorMm = 0, p95ErrorMm = 0, maxErrorMm = 0;
  double meanTrueDisplacementMm = 0, maxTrueDisplacementMm = 0;
  /// Distance of the deformed imposed nodes to the true intraoperative brain boundary, relative to
  /// where they started from the preoperative boundary (mm).
  double meanResidualMm = 0, p95ResidualMm = 0;
  /// The same error over the nodes that truly move more than 2 mm (where the shift is).
  std::size_t movingNodes = 0;
  double movingMeanErrorMm = 0, movingP95ErrorMm = 0, movingMeanTrueDisplacementMm = 0;
};

/// `surface`: the deformed surface in the model frame (points x0 + u, point arrays "Displacement"
/// u and "Imposed"). The model frame is the intraoperative space brought over by `rigidUsed` (the
/// rigid transform the surface was computed with); `trueIntraopToPreop` is the whole truth. The
/// true displacement of x0 is R(T^-1(x0)) - x0 (T inverted by fixed-point iteration). The residual
/// is how far each moved node ends from the true intraoperative brain boundary compared with how
/// far it started from the preoperative one (a mesh node a little off the boundary should stay as
/// far off it): the deformed node is mapped back through the truth, x -> T(R^-1(x)), and the signed
/// distances to the boundary of `brainLabels` in `preopLabels` (a fine grid, no thick-slice bias)
/// at that point and at x0 are compared.
/// std::invalid_argument for a surface without the arrays.
SurfaceDisplacementAccuracy evaluateSurfaceDisplacement(vtkPolyData* surface, const SpatialTransform& trueIntraopToPreop,
                                                        const SpatialTransform& rigidUsed, const LabelImage& preopLabels,
                                                        const std::set<LabelPixel>& brainLabels = {2, 3, 4});

} // namespace brainshift

namespace brainshift {

/// Where the bone is open, in the preoperative frame (LPS): the craniotomy axis through `centre`
/// (on the preoperative brain surface), outward. "Under the craniotomy" is the cylinder of
/// `radiusMm` about that axis: the simulated case opens the bone flap and scalp over a disc of
/// 30 mm radius about it (BrainShiftCaseSimulator's opening radius).
struct CraniotomyFootprint {
  PhysicalPoint centre;
  std::array<double, 3> outwardAxis{};
  double radiusMm = 30.0;
  /// Surface nodes count as under the craniotomy when their preoperative position is inside the
  /// cylinder and no deeper than this below `centre` along the axis (the top of the brain only).
  double nodeDepthMm = 20.0;
};

/// Signed distances of points to a brain boundary: positive where the estimate lies outside the
/// true brain (the sinking under-compensated), negative where inside.
struct BoundaryDistances {
  std::size_t points = 0;
  double signedMeanMm = 0, meanAbsMm = 0, p95AbsMm = 0, maxAbsMm = 0;
};

/// The intraoperative brain boundary under the craniotomy, as the truth has it and as a transform
/// shows it. The boundary of `brainLabels` in `preopLabels` (its signed distance, zero on the voxel
/// faces, on the fine preoperative grid) is carried into the intraoperative space by a transform T
/// (intraop -> preop): the boundary shown there is {y : distance(T(y)) = 0}, which is what the
/// preoperative labels warped by T show, without the intraoperative grid's thick slices. It is
/// sampled where lines parallel to the craniotomy axis, 1 mm apart, first enter the brain from
/// outside (the resection cavity counts as inside: only the outer surface is seen through the
/// opening), and triangulated as a height field over the disc of the footprint's radius + 15 mm.
/// Distances are measured in the intraoperative space (mm), computed in the frame of the true
/// rigid motion (rigidly the same).
class CraniotomyBoundaryEvaluation {
public:
  CraniotomyBoundaryEvaluation(const LabelImage& preopLabels, const SpatialTransform& trueIntraopToPreop,
                               const SpatialTransform& trueRigidIntraopToPreop, const CraniotomyFootprint& footprint,
                               const std::set<LabelPixel>& brainLabels = {2, 3, 4});
  ~CraniotomyBoundaryEvaluation();
  CraniotomyBoundaryEvaluation(const CraniotomyBoundaryEvaluation&) = delete;
  CraniotomyBoundaryEvaluation& operator=(const CraniotomyBoundaryEvaluation&) = delete;

  /// The boundary that `intraopToPreop` shows, against the true one under the craniotomy (the
  /// lines within the radius), both ways: `toShown`, each true boundary point's distance to the
  /// shown boundary (what the shown boundary misses; positive where the shown boundary lies outside
  /// the true one); `toTrue`, each shown boundary point's distance to the true boundary (what it
  /// shows that is not there: an island of preoperative brain left in the gap above a sunken brain
  /// is near no true point, but far from the true boundary; positive where the shown point lies
  /// outside the true brain).
  struct ShownBoundary {
    BoundaryDistances toShown, toTrue;
    /// Both directions' distances together (the average symmetric surface distance); NaN when
    /// either direction has no points (no shown boundary under the craniotomy: not measured).
    double symmetricMeanAbsMm() const;
  };
  ShownBoundary shownBoundary(const SpatialTransform& intraopToPreop) const;

  /// The imposed nodes of `surface` (brainSurface's output in the model frame of `rigidUsed`:
  /// points x0 + u, arrays "Displacement" and "Imposed") whose preoperative position x0 is under
  /// the craniotomy: the distance of the deformed node to the true boundary, less the node's own
  /// signed distance to the preoperative boundary at x0 (a node a little off the boundary should
  /// stay as far off it). `undeformed`: the nodes at x0 instead (the rigid result's reference).
  /// std::invalid_argument for a surface without the arrays.
  BoundaryDistances imposedNodes(vtkPolyData* surface, const SpatialTransform& rigidUsed, bool undeformed = false) const;

  std::size_t trueBoundaryPoints() const;

private:
  struct Data;
  std::unique_ptr<Data> d;
};

} // namespace brainshift
