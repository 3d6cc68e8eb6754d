// The simulate stage's second solve: blocks of the preoperative image matched inside the brain,
// starting where the surface-driven solve puts them, and the solve again with the matches as soft
// constraints, the worst rejected in rounds (Logic/BlockMatching, Logic/BiomechanicalSimulation).
#include "ImageMatchingSolve.h"

#include "ImageMatchConstraints.h"
#include "ModelIO.h"
#include "TransformIO.h"
#include "VolumeIO.h"

#include <vtkCellArray.h>
#include <vtkDoubleArray.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkUnsignedCharArray.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace brainshift {
namespace fs = std::filesystem;

namespace {

/// The matches as points (preoperative frame) for inspection: what was found, what was predicted,
/// how similar, whether the solve kept it and its misfit there.
void writeMatches(const std::vector<BlockMatch>& matches, const ImageMatchConstraints& constraints, const FiniteElementResult& result,
                  const fs::path& file)
{
  vtkNew<vtkPoints> points;
  vtkNew<vtkCellArray> vertices;
  vtkNew<vtkDoubleArray> found, predicted, similarity, misfit;
  vtkNew<vtkUnsignedCharArray> kept;
  found->SetName("Displacement");
  found->SetNumberOfComponents(3);
  predicted->SetName("PredictedDisplacement");
  predicted->SetNumberOfComponents(3);
  similarity->SetName("Similarity");
  misfit->SetName("MisfitMm");
  kept->SetName("Kept");
  for (std::size_t c = 0; c < constraints.constraints.size(); ++c) {
    const BlockMatch& m = matches[constraints.matchOfConstraint[c]];
    const vtkIdType id = points->InsertNextPoint(m.centre[0], m.centre[1], m.centre[2]);
    vertices->InsertNextCell(1, &id);
    found->InsertNextTuple(m.displacement.data());
    predicted->InsertNextTuple(m.predicted.data());
    similarity->InsertNextValue(m.similarity);
    misfit->InsertNextValue(c < result.softConstraintMisfitMm.size() ? result.softConstraintMisfitMm[c] : 0.0);
    kept->InsertNextValue(c < result.softConstraintKept.size() ? result.softConstraintKept[c] : 0);
  }
  vtkNew<vtkPolyData> polyData;
  polyData->SetPoints(points);
  polyData->SetVerts(vertices);
  for (vtkDataArray* array : {static_cast<vtkDataArray*>(found), static_cast<vtkDataArray*>(predicted),
                              static_cast<vtkDataArray*>(similarity), static_cast<vtkDataArray*>(misfit), static_cast<vtkDataArray*>(kept)}) {
    polyData->GetPointData()->AddArray(array);
  }
  writeModel(polyData, file);
}

} // namespace

std::optional<std::string> imageMatchingUnavailable(RunContext& context)
{
  const RunOptions& options = context.options();
  if (options.preopImage.empty() || options.preopLabels.empty() || options.intraopImage.empty()) {
    return "needs --preop-image, --preop-labels and --intraop-image";
  }
  for (const char* file : {"rigid_intraop_to_preop.tfm", "intraop_labels.nii.gz"}) {
    std::error_code ec;
    if (!fs::exists(context.output(file), ec)) return std::string("needs ") + file + " (run rigid and classify first)";
  }
  return std::nullopt;
}

FiniteElementResult runImageDrivenSolve(RunContext& context, vtkUnstructuredGrid* mesh, const FiniteElementJob& job,
                                        const FiniteElementResult& surfaceOnly, const ConstrainedSolve& solve, nlohmann::json& entry,
                                        DisplacementEvidence& evidence)
{
  Stopwatch clock;
  const Configuration& configuration = context.configuration();
  const fs::path rigidFile = context.output("rigid_intraop_to_preop.tfm"), labelsFile = context.output("intraop_labels.nii.gz");
  const SpatialTransform::Pointer rigid = readTransform(rigidFile);
  if (!isLinearTransform(rigid)) throw InputError(rigidFile.string() + ": not a rigid transform");
  const LabelImage::Pointer intraopLabels = context.products().readLabelVolume(labelsFile);
  ImageDrivenSolveInputs inputs;
  inputs.preopImage = &context.preopImage("simulate");
  inputs.preopLabels = &context.preopLabels("simulate");
  inputs.intraopImage = &context.intraopImage("simulate");
  inputs.intraopLabels = intraopLabels.GetPointer();
  inputs.rigidIntraopToPreop = rigid.GetPointer();
  inputs.tumourResected = context.report().hasStage("classify") && context.report().stage("classify").value("tumour_resected", false);
  // A refine pass (the same scan, images and rigid transform; another classification) keeps the
  // matches of this scan's earlier solve under the same tumour decision, those still in the brain
  // of its classification. Matching anew would also learn the intensity remap over the new brain
  // and start from the pass's surface solve: measured on the T2 scans, it changed their TRE by
  // 0.02 mm at most and cost 0.7 s a pass.
  const std::optional<KeptBlockMatches>& kept = context.keptBlockMatches();
  const bool reused = context.warpedPrior() && kept && kept->matching && kept->tumourResected == inputs.tumourResected;
  if (reused) inputs.earlierMatching = kept->matching.get();
  const ImageDrivenSolve solved = brainshift::solveWithImageMatches(mesh, job, surfaceOnly, inputs, configuration, solve);
  const BlockMatchingResult& matching = solved.matching;
  if (!reused) context.keepBlockMatches({std::make_shared<const BlockMatchingResult>(matching), inputs.tumourResected});
  entry = {{"enabled", true},
           {"used", solved.used},
           {"candidates", matching.candidates},
           {"selected", matching.selected},
           {"selection", {{"cell_mm", configuration.blockMatching.selectionCellMm},
                          {"cells", matching.selectionCells},
                          {"cells_with_a_block", matching.selectionCellsWithBlock}}},
           {"matched", matching.matches.size()},
           {"dropped", {{"low_similarity", matching.lowSimilarity}, {"outside_brain", matching.outsideBrain}, {"at_search_edge", matching.atSearchEdge}}},
           {"deformed_windows", {{"tried", matching.deformedWindows}, {"taken", matching.deformedWindowsTaken}}},
           {"constraints", solved.constraints.constraints.size()},
           {"excluded_labels", inputs.tumourResected ? std::vector<int>{4} : std::vector<int>{}},
           {"remap_correlation_ratio", matching.remapCorrelationRatio},
           {"remap_seconds", matching.remapSeconds},
           {"selection_seconds", matching.selectionSeconds},
           {"matching_seconds", matching.matchingSeconds},
           {"smoothing_mm", configuration.blockMatching.smoothingMm},
           {"stiffness_n_per_mm", configuration.blockMatching.stiffnessNPerMm},
           {"matches_from", reused ? "this scan's earlier solve, held against this pass's classification" : "matched anew"}};
  if (reused) {
    context.say("simulate: %zu of the earlier solve's %zu matches still in the brain of this classification (%.2f s)\n",
                matching.matches.size(), kept->matching->matches.size(), matching.selectionSeconds);
  } else {
    context.say("simulate: %zu of %zu blocks matched (%zu low similarity, %zu outside the brain, %zu at the search edge; %zu of %zu "
                "tried in the window the surface-driven solve deforms matched better there) in %.2f s\n",
                matching.matches.size(), matching.selected, matching.lowSimilarity, matching.outsideBrain, matching.atSearchEdge,
                matching.deformedWindowsTaken, matching.deformedWindows, matching.remapSeconds + matching.selectionSeconds + matching.matchingSeconds);
  }
  if (solved.used) {
    const FiniteElementResult& result = solved.result;
    const std::size_t kept = keptSoftConstraints(result);
    entry["kept"] = kept;
    entry["rejected"] = solved.constraints.constraints.size() - kept;
    entry["solves"] = result.keptPerRound.size();
    entry["kept_per_solve"] = result.keptPerRound;
    entry["rms_misfit_surface_only_mm"] = solved.rmsMisfitSurfaceOnlyMm;
    entry["rms_misfit_per_solve_mm"] = result.rmsMisfitPerRoundMm;
    entry["mean_node_change_mm"] = solved.meanNodeChangeMm;
    entry["solve_seconds"] = result.setupSeconds + result.solveSeconds;
    writeMatches(matching.matches, solved.constraints, result, context.output("block_matches.vtp"));
    evidence = solved.evidence;
    context.say("simulate: %zu of %zu matches kept after %zu solves; misfit %.2f mm (surface alone) -> %.2f mm (kept)\n", kept,
                solved.constraints.constraints.size(), result.keptPerRound.size(), solved.rmsMisfitSurfaceOnlyMm,
                result.rmsMisfitPerRoundMm.empty() ? 0.0 : result.rmsMisfitPerRoundMm.back());
  }
  entry["wall_seconds"] = clock.seconds();
  return solved.result;
}

} // namespace brainshift
