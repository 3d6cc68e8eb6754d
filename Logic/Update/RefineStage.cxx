// The refine stage: a classification that follows the brain where it went (Warfield et al.'s
// adaptive, template-moderated classification). The first classification's spatial prior is the
// preoperative anatomy through the rigid transform alone; under a large shift it says "brain"
// where fluid and air now lie, and the surface stops short of the sunken brain. After a solve, the
// preoperative labels warped by it are a prior much nearer the truth: classify, fit the surface
// and solve again, until the imposed surface displacement settles.
#include "BrainShiftErrors.h"
#include "DeformationField.h"
#include "ModelIO.h"
#include "UpdatePipeline.h"
#include "TransformIO.h"
#include "VolumeIO.h"
#include "WarpedPriorRefinement.h"

#include <vtkDataArray.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkUnstructuredGrid.h>

#include <cmath>
#include <cstdio>
#include <map>

namespace brainshift {
namespace fs = std::filesystem;

namespace {

/// The imposed displacement of each mesh node on the brain surface file (model frame, mm).
std::map<vtkIdType, std::array<double, 3>> imposedDisplacements(RunContext& context, const fs::path& surfaceFile)
{
  vtkSmartPointer<vtkPolyData> surface = vtkPolyData::SafeDownCast(context.products().readModel(surfaceFile));
  if (!surface) throw InputError(surfaceFile.string() + ": not a surface (vtkPolyData)");
  vtkDataArray* displacement = surface->GetPointData()->GetArray("Displacement");
  vtkDataArray* node = surface->GetPointData()->GetArray("MeshNodeId");
  vtkDataArray* imposed = surface->GetPointData()->GetArray("Imposed");
  if (!displacement || !node || !imposed) {
    throw InputError(surfaceFile.string() + ": lacks the point arrays Displacement, MeshNodeId and Imposed");
  }
  std::map<vtkIdType, std::array<double, 3>> result;
  for (vtkIdType i = 0; i < surface->GetNumberOfPoints(); ++i) {
    if (imposed->GetComponent(i, 0) < 0.5) continue;
    double u[3];
    displacement->GetTuple(i, u);
    result[vtkIdType(std::llround(node->GetComponent(i, 0)))] = {u[0], u[1], u[2]};
  }
  return result;
}

struct DisplacementChange {
  double meanMm = 0, maxMm = 0;
  std::size_t nodes = 0;
};

/// How far the imposed displacement moved between two passes, over the moving part of the surface
/// (nodes imposed in both passes, displaced by more than 1 mm in either): the still remainder would
/// dilute the mean.
DisplacementChange changeBetween(const std::map<vtkIdType, std::array<double, 3>>& before,
                                 const std::map<vtkIdType, std::array<double, 3>>& after)
{
  DisplacementChange change;
  double sum = 0;
  auto length = [](const std::array<double, 3>& u) { return std::hypot(u[0], u[1], u[2]); };
  for (const auto& [node, u] : after) {
    const auto found = before.find(node);
    if (found == before.end() || std::max(length(u), length(found->second)) <= 1.0) continue;
    const double d = std::hypot(u[0] - found->second[0], u[1] - found->second[1], u[2] - found->second[2]);
    sum += d;
    change.maxMm = std::max(change.maxMm, d);
    ++change.nodes;
  }
  change.meanMm = change.nodes ? sum / double(change.nodes) : 0.0;
  return change;
}

struct WarpedPrior {
  LabelImage::Pointer labels; ///< the preoperative labels warped onto the intraoperative grid by the solve
  MaskImage::Pointer moved;   ///< within the reach of where the solve moved the tissue by more than MovedMm
};
/// Where the first solve stopped short (fluid taken for brain), it moved nothing at all; the
/// corrections lie next to the tissue it did move, within about the shift itself (the reach).
constexpr double MovedMm = 1.0;

/// The preoperative labels warped onto the intraoperative grid by the solved mesh.
WarpedPrior labelsWarpedBySolve(RunContext& context, double reachMm)
{
  const fs::path meshFile = context.output("mesh.vtu"), rigidFile = context.output("rigid_intraop_to_preop.tfm");
  vtkSmartPointer<vtkUnstructuredGrid> mesh = vtkUnstructuredGrid::SafeDownCast(context.products().readModel(meshFile));
  if (!mesh) throw InputError(meshFile.string() + ": not a tetrahedral mesh (vtkUnstructuredGrid)");
  if (!mesh->GetPointData()->GetArray("Displacement")) {
    throw InputError(meshFile.string() + ": no Displacement; run `brainshift simulate` on this output folder first");
  }
  const SpatialTransform::Pointer rigid = readTransform(rigidFile);
  if (!isLinearTransform(rigid)) throw InputError(rigidFile.string() + ": not a rigid transform");
  const DeformationField deformation = intraopToPreopField(mesh, *rigid, ImageGeometry::of(&context.intraopImage("refine")),
                                                           DeformationFieldParameters{}, meshFile.string());
  return {warpLabelVolume(context.preopLabels("refine"), *deformation.field), reachMm > 0 ? regionMovedBySolve(*deformation.field, *rigid, MovedMm, reachMm) : nullptr};
}

/// The passes to run: the configured number, or ("auto") one where the first classification
/// found this scan's fluid brighter than its parenchyma, none elsewhere; and why.
std::pair<unsigned, std::string> refinementPasses(RunContext& context)
{
  const std::optional<unsigned> configured = context.configuration().classificationRefinementPasses;
  if (configured) return {*configured, "configured"};
  const nlohmann::json classify = context.report().hasStage("classify") ? context.report().stage("classify") : nlohmann::json::object();
  const bool fluidBright = classify.contains("contrast") && classify["contrast"].value("fluid", "") == "brighter than the parenchyma";
  return fluidBright ? std::pair<unsigned, std::string>{1, "auto: the scan's fluid is brighter than its parenchyma"}
                     : std::pair<unsigned, std::string>{0, "auto: the scan's fluid is darker than its parenchyma"};
}

} // namespace

void runRefineStage(RunContext& context)
{
  Stopwatch clock;
  const Configuration& configuration = context.configuration();
  const auto [maximumPasses, passesFrom] = refinementPasses(context);
  const double tolerance = configuration.classificationRefinementToleranceMm;
  nlohmann::json passes = nlohmann::json::array();
  bool settled = false;
  for (const auto& [needed, stage] : {std::pair<const char*, const char*>{"rigid_intraop_to_preop.tfm", "rigid"},
                                      {"intraop_labels.nii.gz", "classify"}, {"mesh.vtu", "mesh"},
                                      {"brain_surface.vtp", "surface"}}) {
    std::error_code ec;
    if (!fs::exists(context.output(needed), ec)) {
      throw InputError(context.output(needed).string() + ": not found; run `brainshift " + stage + "` (and the stages after it) on this output folder first");
    }
  }
  // The first classification (through the rigid prior) stays where the solve moved nothing.
  const LabelImage::Pointer anchor = context.products().readLabelVolume(context.output("intraop_labels.nii.gz"));
  // What the first pass did once for the whole scan stays said in its stages' entries.
  const nlohmann::json firstSurface = context.report().hasStage("surface") ? context.report().stage("surface") : nlohmann::json::object();
  const nlohmann::json firstSimulate = context.report().hasStage("simulate") ? context.report().stage("simulate") : nlohmann::json::object();
  const nlohmann::json firstClassify = context.report().hasStage("classify") ? context.report().stage("classify") : nlohmann::json::object();
  const std::optional<bool> firstTumourDecision =
    firstClassify.contains("tumour_resected") && firstClassify["tumour_resected"].is_boolean()
      ? std::optional<bool>(firstClassify["tumour_resected"].get<bool>())
      : std::nullopt;
  auto keepFirstPassFacts = [&] {
    nlohmann::json surface = context.report().stage("surface");
    for (const char* key : {"preop_boundary_from", "preop_boundary_seconds"}) {
      if (firstSurface.contains(key)) surface[key] = firstSurface[key];
    }
    context.report().setStage("surface", surface);
    nlohmann::json simulate = context.report().stage("simulate");
    if (firstSimulate.value("worker_prepared", false)) simulate["worker_prepared"] = true;
    context.report().setStage("simulate", simulate);
  };
  try {
    for (unsigned pass = 1; pass <= maximumPasses && !settled; ++pass) {
      Stopwatch passClock;
      const auto before = imposedDisplacements(context, context.output("brain_surface.vtp"));
      const WarpedPrior prior = labelsWarpedBySolve(context, configuration.classificationRefinementReachMm);
      context.setWarpedPrior(prior.labels, int(pass), configuration.classificationRefinementReachMm > 0 ? prior.moved : nullptr, anchor,
                             firstTumourDecision);
      const double priorSeconds = passClock.seconds();
      runClassifyStage(context);
      runSurfaceStage(context);
      runSimulateStage(context);
      keepFirstPassFacts();
      const DisplacementChange change = changeBetween(before, imposedDisplacements(context, context.output("brain_surface.vtp")));
      settled = change.meanMm < tolerance;
      const nlohmann::json& classify = context.report().stage("classify");
      passes.push_back({{"pass", pass},
                        {"wall_seconds", passClock.seconds()},
                        {"prior_seconds", priorSeconds},
                        {"classify_seconds", classify["wall_seconds"]},
                        {"surface_seconds", context.report().stage("surface")["wall_seconds"]},
                        {"simulate_seconds", context.report().stage("simulate")["wall_seconds"]},
                        {"tumour_resected", classify["tumour_resected"]},
                        {"imposed_nodes", context.report().stage("surface")["imposed_nodes"]},
                        {"mean_change_mm", change.meanMm},
                        {"max_change_mm", change.maxMm},
                        {"compared_nodes", change.nodes}});
      context.say("refine pass %u: the imposed surface moved %.2f mm mean (%.2f max), %.2f s\n", pass, change.meanMm,
                  change.maxMm, passClock.seconds());
      context.report().save();
    }
  } catch (...) {
    context.setWarpedPrior(nullptr, 0);
    throw;
  }
  context.setWarpedPrior(nullptr, 0);
  context.report().setStage("refine", {{"wall_seconds", clock.seconds()},
                                       {"passes", passes.size()},
                                       {"maximum_passes", maximumPasses},
                                       {"passes_from", passesFrom},
                                       {"tolerance_mm", tolerance},
                                       {"settled", settled || maximumPasses == 0},
                                       {"per_pass", passes}});
  if (!settled && maximumPasses > 0) {
    char warning[160];
    std::snprintf(warning, sizeof(warning), "refine: the brain boundary still moved %.2f mm mean in the last of %u passes",
                  passes.back()["mean_change_mm"].get<double>(), maximumPasses);
    context.report().addWarning(warning);
  }
}

} // namespace brainshift
