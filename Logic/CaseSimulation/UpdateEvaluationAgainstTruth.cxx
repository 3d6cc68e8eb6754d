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
  if (fs::exists(out / "displacement_uncertainty_mm.nii.gz", ec) && fs::exists(out / "displacement_intraop_to_preop.nrrd", ec)) {
    evaluation["uncertainty"] = uncertaintyEvaluation(simulated, out);
  }
  return evaluation;
}

} // namespace brainshift
