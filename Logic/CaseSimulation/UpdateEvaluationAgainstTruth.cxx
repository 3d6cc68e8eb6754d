#include "UpdateEvaluationAgainstTruth.h"

#include "LabelOverlap.h"
#include "LandmarkEvaluation.h"
#include "ModelIO.h"
#include "SurfaceDisplacementEvaluation.h"
#include "TransformIO.h"
#include "UncertaintyEvaluation.h"
#include "VolumeIO.h"

#include <itkIdentityTransform.h>

#include <vtkPolyData.h>

#include <cmath>

#include <utility>

namespace brainshift {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {
json evaluationOf(const SpatialTransform& transform, const std::vector<LandmarkPair>& landmarks)
{
  return json::parse(toJsonText(evaluateTransform(transform, landmarks)));
}
} // namespace

json transformEvaluations(const SimulatedCase& simulated, const fs::path& updateFolder)
{
  json transforms = json::object();
  auto identity = itk::IdentityTransform<double, 3>::New();
  transforms["identity"] = evaluationOf(*identity, simulated.landmarks);
  transforms["truth_rigid"] = evaluationOf(*simulated.rigidIntraopToPreop, simulated.landmarks);
  transforms["truth"] = evaluationOf(*simulated.intraopToPreop, simulated.landmarks);
  std::error_code ec;
  for (const auto& [key, file] : {std::pair<std::string, fs::path>{"brainshift_rigid", updateFolder / "rigid_intraop_to_preop.tfm"},
                                  {"brainshift", updateFolder / "intraop_to_preop.h5"},
                                  {"brainshift_rejected_update", updateFolder / "rejected_intraop_to_preop.h5"}}) {
    if (fs::exists(file, ec)) transforms[key] = evaluationOf(*readTransform(file), simulated.landmarks);
  }
  return transforms;
}

json classificationEvaluation(const SimulatedCase& simulated, const fs::path& classifiedFile)
{
  const LabelImage::Pointer classified = readLabelVolume(classifiedFile);
  const LabelImage& truthLabels = *simulated.intraopLabels;
  return {{"brain_dice", diceCoefficient(*classified, truthLabels, {2, 3, 4})},
          {"ventricle_dice", diceCoefficient(*classified, truthLabels, {3})},
          {"parenchyma_dice", diceCoefficient(*classified, truthLabels, {2})},
          {"brain_surface_distance_mm", meanSurfaceDistanceMm(*classified, truthLabels, {2, 3, 4})}};
}

json surfaceEvaluation(const SimulatedCase& simulated, const fs::path& updateFolder)
{
  vtkSmartPointer<vtkPolyData> surface = vtkPolyData::SafeDownCast(readModel(updateFolder / "brain_surface.vtp"));
  const SpatialTransform::Pointer rigid = readTransform(updateFolder / "rigid_intraop_to_preop.tfm");
  if (!surface) return nullptr;
  const SurfaceDisplacementAccuracy a = evaluateSurfaceDisplacement(surface, *simulated.intraopToPreop, *rigid, *simulated.preopLabels);
  return {{"imposed_nodes", a.nodes},
          {"mean_error_mm", a.meanErrorMm},
          {"median_error_mm", a.medianErrorMm},
          {"p95_error_mm", a.p95ErrorMm},
          {"max_error_mm", a.maxErrorMm},
          {"true_mean_displacement_mm", a.meanTrueDisplacementMm},
          {"true_max_displacement_mm", a.maxTrueDisplacementMm},
          {"moving_nodes", a.movingNodes},
          {"moving_mean_error_mm", a.movingMeanErrorMm},
          {"moving_p95_error_mm", a.movingP95ErrorMm},
          {"moving_true_mean_displacement_mm", a.movingMeanTrueDisplacementMm},
          {"residual_to_true_boundary_mm", a.meanResidualMm},
          {"p95_residual_to_true_boundary_mm", a.p95ResidualMm}};
}

namespace {
json boundaryDistancesJson(const BoundaryDistances& b)
{
  return {{"points", b.points}, {"signed_mean_mm", b.signedMeanMm}, {"mean_abs_mm", b.meanAbsMm}, {"p95_abs_mm", b.p95AbsMm},
          {"max_abs_mm", b.maxAbsMm}};
}

/// From the true points (the entry's own figures, as before), from the shown points, and both.
json shownBoundaryJson(const CraniotomyBoundaryEvaluation::ShownBoundary& b)
{
  json entry = boundaryDistancesJson(b.toShown);
  entry["from_shown"] = boundaryDistancesJson(b.toTrue);
  const double both = b.symmetricMeanAbsMm();
  entry["symmetric_mean_abs_mm"] = std::isfinite(both) ? json(both) : json(nullptr); // null: a direction unmeasured
  return entry;
}

constexpr const char* kUnderCraniotomy =
  "under the craniotomy: within radius_mm of the craniotomy axis (through craniotomy_centre_lps along craniotomy_axis_lps, "
  "outward, in the preoperative frame and so, by the true rigid motion, in the intraoperative space), where the simulated "
  "case opened the bone. The brain boundary there is the outer surface of labels 2-4 (the resection cavity counted as "
  "inside) where lines parallel to the axis, 1 mm apart, first enter the brain; a transform T (intraop -> preop) shows the "
  "preoperative boundary at {y : d(T(y)) = 0}, d the preoperative signed distance on its fine grid (sub-voxel, no "
  "thick slices). shown.*: each true boundary point's distance to the boundary the transform shows, positive where the "
  "shown boundary lies outside the true one (the sinking under-compensated); shown.*.from_shown: each shown boundary "
  "point's distance to the true boundary, positive where it lies outside the true brain (what the transform shows that is "
  "not there: preoperative brain left in the gap above a sunken brain); shown.*.symmetric_mean_abs_mm: both directions' "
  "distances together (the average symmetric surface distance). imposed_nodes: the active surface's imposed "
  "nodes whose preoperative position is within the radius and at most node_depth_mm below the centre, the deformed "
  "node's signed distance to the true boundary (positive outside) less its own preoperative offset; "
  "imposed_nodes_undeformed: the same nodes before their displacement (the rigid result).";
} // namespace

json boundaryUnderCraniotomyEvaluation(const SimulatedCase& simulated, const fs::path& updateFolder)
{
  CraniotomyFootprint footprint;
  footprint.centre = simulated.figures.craniotomyCentre;
  footprint.outwardAxis = simulated.figures.craniotomyAxis;
  const CraniotomyBoundaryEvaluation evaluation(*simulated.preopLabels, *simulated.intraopToPreop, *simulated.rigidIntraopToPreop, footprint);
  json shown = json::object();
  shown["truth_rigid"] = shownBoundaryJson(evaluation.shownBoundary(*simulated.rigidIntraopToPreop));
  std::error_code ec;
  for (const auto& [key, file] : {std::pair<std::string, fs::path>{"brainshift_rigid", updateFolder / "rigid_intraop_to_preop.tfm"},
                                  {"brainshift", updateFolder / "intraop_to_preop.h5"},
                                  {"brainshift_rejected_update", updateFolder / "rejected_intraop_to_preop.h5"}}) {
    if (fs::exists(file, ec)) shown[key] = shownBoundaryJson(evaluation.shownBoundary(*readTransform(file)));
  }
  json result = {{"definition", kUnderCraniotomy},
                 {"craniotomy_centre_lps", {footprint.centre[0], footprint.centre[1], footprint.centre[2]}},
                 {"craniotomy_axis_lps", footprint.outwardAxis},
                 {"radius_mm", footprint.radiusMm},
                 {"node_depth_mm", footprint.nodeDepthMm},
                 {"true_boundary_points", evaluation.trueBoundaryPoints()},
                 {"shown", shown}};
  const fs::path surfaceFile = updateFolder / "brain_surface.vtp", rigidFile = updateFolder / "rigid_intraop_to_preop.tfm";
  if (fs::exists(surfaceFile, ec) && fs::exists(rigidFile, ec)) {
    vtkSmartPointer<vtkPolyData> surface = vtkPolyData::SafeDownCast(readModel(surfaceFile));
    if (surface) {
      const SpatialTransform::Pointer rigid = readTransform(rigidFile);
      result["imposed_nodes"] = boundaryDistancesJson(evaluation.imposedNodes(surface, *rigid));
      result["imposed_nodes_undeformed"] = boundaryDistancesJson(evaluation.imposedNodes(surface, *rigid, true));
    }
  }
  return result;
}

json uncertaintyEvaluation(const SimulatedCase& simulated, const fs::path& updateFolder)
{
  const UncertaintyValidation u =
    validateUncertainty(*readDisplacementField(updateFolder / "displacement_intraop_to_preop.nrrd"), *simulated.intraopToPreop,
                        *readScalarVolume(updateFolder / "displacement_uncertainty_mm.nii.gz"), *simulated.intraopLabels);
  const json evaluation = {{"voxels", u.voxels},
                           {"rank_correlation", u.rankCorrelation},
                           {"mean_true_error_mm", u.meanTrueErrorMm},
                           {"mean_estimate_mm", u.meanEstimateMm},
                           {"share_called_below_1mm", u.shareCalledBelow1Mm},
                           {"called_below_1mm_truly_below_1_5mm", u.calledBelow1MmTrulyBelow1_5Mm},
                           {"true_error_where_called_above_2mm", u.trueErrorWhereCalledAbove2MmMm},
                           {"true_error_file", "true_error_mm.nii.gz"}};
  writeScalarVolume(u.trueError, updateFolder / "true_error_mm.nii.gz");
  return evaluation;
}

json evaluateUpdateAgainstTruth(const SimulatedCase& simulated, const fs::path& updateFolder, const std::string& landmarksFile,
                                bool pipelineComplete)
{
  json evaluation = {{"landmarks", landmarksFile},
                     {"pairs", simulated.landmarks.size()},
                     {"pipeline_complete", pipelineComplete},
                     {"transforms", transformEvaluations(simulated, updateFolder)}};
  const fs::path& out = updateFolder;
  std::error_code ec;
  if (fs::exists(out / "intraop_labels.nii.gz", ec)) {
    evaluation["classification"] = classificationEvaluation(simulated, out / "intraop_labels.nii.gz");
  }
  if (fs::exists(out / "brain_surface.vtp", ec) && fs::exists(out / "rigid_intraop_to_preop.tfm", ec)) {
    if (json surface = surfaceEvaluation(simulated, out); !surface.is_null()) evaluation["surface"] = std::move(surface);
  }
  evaluation["boundary_under_craniotomy"] = boundaryUnderCraniotomyEvaluation(simulated, out);
  if (fs::exists(out / "displacement_uncertainty_mm.nii.gz", ec) && fs::exists(out / "displacement_intraop_to_preop.nrrd", ec)) {
    evaluation["uncertainty"] = uncertaintyEvaluation(simulated, out);
  }
  return evaluation;
}

} // namespace brainshift
