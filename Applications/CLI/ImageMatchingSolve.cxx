// The simulate stage's second solve: blocks of the preoperative image matched inside the brain,
// starting where the surface-driven solve puts them, and the solve again with the matches as soft
// constraints, the worst rejected in rounds (Logic/BlockMatching, Logic/Biomechanics).
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

namespace brainshift::cli {
namespace fs = std::filesystem;

namespace {

BlockMatchingParameters blockMatchingParametersFrom(const Configuration& configuration, bool tumourResected)
{
  const Configuration::BlockMatching& c = configuration.blockMatching;
  BlockMatchingParameters p;
  p.blockHalfSizeMm = c.blockHalfSizeMm;
  p.blockSpacingMm = c.blockSpacingMm;
  p.selectedShare = c.selectedShare;
  p.maximumBlocks = std::size_t(c.maximumBlocks);
  p.searchRadiusMm = c.searchRadiusMm;
  p.minimumSimilarity = c.minimumSimilarity;
  if (tumourResected) p.excludedLabels = {4}; // its tissue is gone from the scan
  return p;
}

SoftConstraintRejection rejectionFrom(const Configuration& configuration)
{
  const Configuration::BlockMatching& c = configuration.blockMatching;
  return {int(c.rejectionRounds), c.rejectionFraction, c.outlierFactor, c.rejectionFloorMm};
}

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

/// Root mean square of |u(p) - target| over the constraints under the nodal displacements.
double rmsMisfit(const FiniteElementJob& job, const std::vector<SoftConstraint>& constraints, const std::vector<double>& displacements)
{
  if (constraints.empty()) return 0;
  double sum = 0;
  for (const SoftConstraint& c : constraints) {
    double r[3] = {-c.target[0], -c.target[1], -c.target[2]};
    for (int k = 0; k < 4; ++k) {
      const std::size_t node = std::size_t(job.tetrahedra[4 * std::size_t(c.tetrahedron) + std::size_t(k)]);
      for (int d = 0; d < 3; ++d) r[d] += c.weights[std::size_t(k)] * displacements[3 * node + std::size_t(d)];
    }
    sum += r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
  }
  return std::sqrt(sum / double(constraints.size()));
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

FiniteElementResult solveWithImageMatches(RunContext& context, vtkUnstructuredGrid* mesh, const FiniteElementJob& job,
                                          const FiniteElementResult& surfaceOnly, const ConstrainedSolve& solve, nlohmann::json& entry,
                                          DisplacementEvidence& evidence)
{
  Stopwatch clock;
  const Configuration& configuration = context.configuration();
  const fs::path rigidFile = context.output("rigid_intraop_to_preop.tfm"), labelsFile = context.output("intraop_labels.nii.gz");
  const SpatialTransform::Pointer rigid = readTransform(rigidFile);
  if (!isLinearTransform(rigid)) throw InputError(rigidFile.string() + ": not a rigid transform");
  const LabelImage::Pointer intraopLabels = readLabelVolume(labelsFile);
  const bool tumourResected = context.report().hasStage("classify") && context.report().stage("classify").value("tumour_resected", false);
  const MeshPointLocator locator(mesh);
  const DisplacementPrediction prediction = [&](const PhysicalPoint& x) {
    return locator.interpolate(surfaceOnly.displacements, x).value_or(std::array<double, 3>{0, 0, 0});
  };
  BlockMatchingParameters parameters = blockMatchingParametersFrom(configuration, tumourResected);
  parameters.largestPredictedMm = 0;
  for (std::size_t i = 0; i + 2 < surfaceOnly.displacements.size(); i += 3) {
    parameters.largestPredictedMm = std::max(parameters.largestPredictedMm, std::sqrt(std::pow(surfaceOnly.displacements[i], 2) +
                                                                                       std::pow(surfaceOnly.displacements[i + 1], 2) +
                                                                                       std::pow(surfaceOnly.displacements[i + 2], 2)));
  }
  parameters.largestPredictedMm = std::min(parameters.largestPredictedMm, 200.0);
  const BlockMatchingResult matching =
    matchBlocks(context.preopImage("simulate"), context.preopLabels("simulate"), context.intraopImage("simulate"), *intraopLabels, *rigid,
                prediction, parameters);
  const ImageMatchConstraints constraints = softConstraintsFromMatches(locator, matching.matches, configuration.blockMatching.stiffnessNPerMm);
  entry = {{"enabled", true},
           {"candidates", matching.candidates},
           {"selected", matching.selected},
           {"matched", matching.matches.size()},
           {"dropped", {{"low_similarity", matching.lowSimilarity}, {"outside_brain", matching.outsideBrain}, {"at_search_edge", matching.atSearchEdge}}},
           {"constraints", constraints.constraints.size()},
           {"excluded_labels", tumourResected ? std::vector<int>{4} : std::vector<int>{}},
           {"remap_correlation_ratio", matching.remapCorrelationRatio},
           {"remap_seconds", matching.remapSeconds},
           {"selection_seconds", matching.selectionSeconds},
           {"matching_seconds", matching.matchingSeconds},
           {"stiffness_n_per_mm", configuration.blockMatching.stiffnessNPerMm}};
  std::printf("  simulate: %zu of %zu blocks matched (%zu low similarity, %zu outside the brain, %zu at the search edge) in %.2f s\n",
              matching.matches.size(), matching.selected, matching.lowSimilarity, matching.outsideBrain, matching.atSearchEdge,
              matching.remapSeconds + matching.selectionSeconds + matching.matchingSeconds);
  if (constraints.constraints.empty()) {
    entry["used"] = false;
    entry["wall_seconds"] = clock.seconds();
    return surfaceOnly;
  }
  FiniteElementJob constrained = job;
  constrained.softConstraints = constraints.constraints;
  constrained.rejection = rejectionFrom(configuration);
  const std::size_t matchConstraints = constrained.softConstraints.size();
  const FiniteElementResult result = solve(constrained);
  std::size_t kept = 0;
  for (std::uint8_t k : result.softConstraintKept) kept += k;
  double change = 0;
  for (std::size_t i = 0; i + 2 < result.displacements.size(); i += 3) {
    change += std::sqrt(std::pow(result.displacements[i] - surfaceOnly.displacements[i], 2) +
                        std::pow(result.displacements[i + 1] - surfaceOnly.displacements[i + 1], 2) +
                        std::pow(result.displacements[i + 2] - surfaceOnly.displacements[i + 2], 2));
  }
  entry["used"] = true;
  entry["kept"] = kept;
  entry["rejected"] = matchConstraints - kept;
  entry["solves"] = result.keptPerRound.size();
  entry["kept_per_solve"] = result.keptPerRound;
  entry["rms_misfit_surface_only_mm"] = rmsMisfit(job, constraints.constraints, surfaceOnly.displacements);
  entry["rms_misfit_per_solve_mm"] = result.rmsMisfitPerRoundMm;
  entry["mean_node_change_mm"] = change / double(std::max<std::size_t>(1, result.displacements.size() / 3));
  entry["solve_seconds"] = result.setupSeconds + result.solveSeconds;
  writeMatches(matching.matches, constraints, result, context.output("block_matches.vtp"));
  for (std::size_t c = 0; c < matchConstraints && c < result.softConstraintMisfitMm.size(); ++c) {
    const PhysicalPoint& x = matching.matches[constraints.matchOfConstraint[c]].centre;
    const std::array<double, 3> point{x[0], x[1], x[2]};
    if (result.softConstraintKept[c]) evidence.points.push_back(point);
    evidence.misfitPoints.push_back(point);
    evidence.misfitsMm.push_back(result.softConstraintMisfitMm[c]);
  }
  entry["wall_seconds"] = clock.seconds();
  std::printf("  simulate: %zu of %zu matches kept after %zu solves; misfit %.2f mm (surface alone) -> %.2f mm (kept)\n", kept,
              constraints.constraints.size(), result.keptPerRound.size(), entry["rms_misfit_surface_only_mm"].get<double>(),
              result.rmsMisfitPerRoundMm.empty() ? 0.0 : result.rmsMisfitPerRoundMm.back());
  return result;
}

} // namespace brainshift::cli
