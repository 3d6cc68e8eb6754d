#pragma once
// Accuracy of the brain surface's displacements (the active surface's output) against a known
// deformation: the simulated case's truth.
#include "ImageTypes.h"
#include "TransformIO.h"

#include <vtkPolyData.h>

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
