#pragma once
// An update folder (what `register` wrote) judged against the truth of the simulated case it ran
// on: the target registration errors of the reference transforms and of those the run wrote, and,
// where the run wrote them, the classification, the brain surface's displacements and the
// confidence map against the truth. The document is the demo's evaluation.json; the command line
// prints its figures.
#include "BrainShiftCaseSimulator.h"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <string>

namespace brainshift {

/// evaluation.json of `updateFolder`: "landmarks" (`landmarksFile`, as the document names the
/// case's landmarks), "pairs", "pipeline_complete", "transforms" (each transform's target
/// registration error: "identity", "truth_rigid", "truth", and "brainshift_rigid", "brainshift",
/// "brainshift_rejected_update" where the folder holds them), and where the run wrote their files
/// "classification", "surface" and "uncertainty" (which also writes the true error of the update
/// as updateFolder/true_error_mm.nii.gz); always "boundary_under_craniotomy".
nlohmann::json evaluateUpdateAgainstTruth(const SimulatedCase& simulated, const std::filesystem::path& updateFolder,
                                          const std::string& landmarksFile, bool pipelineComplete);

/// The target registration errors on the case's landmarks of the identity, the true rigid and the
/// true transform, and of the rigid, whole and rejected transforms the update folder holds.
nlohmann::json transformEvaluations(const SimulatedCase& simulated, const std::filesystem::path& updateFolder);

/// The classification (a label file on the intraoperative grid) against the true intraoperative
/// labels: Dice of the brain, ventricles and parenchyma, and the brain's mean surface distance.
nlohmann::json classificationEvaluation(const SimulatedCase& simulated, const std::filesystem::path& classifiedFile);

/// The brain surface's displacements (updateFolder/brain_surface.vtp, in the model frame of
/// updateFolder/rigid_intraop_to_preop.tfm) against the truth; null when the file holds no surface.
nlohmann::json surfaceEvaluation(const SimulatedCase& simulated, const std::filesystem::path& updateFolder);

/// The intraoperative brain boundary under the craniotomy (CraniotomyBoundaryEvaluation, the
/// case's craniotomy centre and axis, the 30 mm radius of its bone opening): "definition" (what is
/// measured, in words), the footprint, "true_boundary_points", "shown" (the boundary the true rigid
/// motion and the folder's rigid, whole and rejected transforms show, where it holds them, against
/// the true one) and, where the folder holds brain_surface.vtp and rigid_intraop_to_preop.tfm,
/// "imposed_nodes" and "imposed_nodes_undeformed". Each figure: "points", "signed_mean_mm",
/// "mean_abs_mm", "p95_abs_mm", "max_abs_mm".
nlohmann::json boundaryUnderCraniotomyEvaluation(const SimulatedCase& simulated, const std::filesystem::path& updateFolder);

/// The confidence map (displacement_uncertainty_mm.nii.gz) against the true error of the update's
/// displacement field (displacement_intraop_to_preop.nrrd), which it writes as true_error_mm.nii.gz.
nlohmann::json uncertaintyEvaluation(const SimulatedCase& simulated, const std::filesystem::path& updateFolder);

} // namespace brainshift
