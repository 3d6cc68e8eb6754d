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

#include <vtkCellData.h>
#include <vtkDataArray.h>
#include <vtkPointData.h>
#include <vtkPolyData.h>
#include <vtkUnstructuredGrid.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <optional>

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

/// The confidence map with the last pass's disagreement in it: each imposed node whose imposed
/// displacement changed between the last two passes is evidence, misfit by that change, beside the
/// solve's own (DisplacementUncertainty.h: the local root mean square misfit around a node). Where
/// the passes disagree, neither is known better than by their difference. Returns the nodes added.
std::size_t addPassDisagreementToUncertainty(RunContext& context, const std::map<vtkIdType, std::array<double, 3>>& before,
                                             const std::map<vtkIdType, std::array<double, 3>>& after)
{
  if (!context.solveEvidence()) return 0;
  const fs::path meshFile = context.output("mesh.vtu");
  vtkSmartPointer<vtkUnstructuredGrid> mesh = vtkUnstructuredGrid::SafeDownCast(context.products().readModel(meshFile));
  vtkDataArray* displacement = mesh ? mesh->GetPointData()->GetArray("Displacement") : nullptr;
  vtkDataArray* uncertainty = mesh ? mesh->GetPointData()->GetArray("DisplacementUncertainty") : nullptr;
  if (!displacement || !uncertainty) return 0;
  DisplacementEvidence evidence = *context.solveEvidence();
  std::size_t added = 0;
  for (const auto& [node, u] : after) {
    const auto found = before.find(node);
    if (found == before.end() || node < 0 || node >= mesh->GetNumberOfPoints()) continue;
    double x[3];
    mesh->GetPoint(node, x);
    evidence.misfitPoints.push_back({x[0], x[1], x[2]});
    evidence.misfitsMm.push_back(std::hypot(u[0] - found->second[0], u[1] - found->second[1], u[2] - found->second[2]));
    ++added;
  }
  std::vector<double> nodes(3 * std::size_t(mesh->GetNumberOfPoints())), displacements(nodes.size());
  for (vtkIdType i = 0; i < mesh->GetNumberOfPoints(); ++i) {
    mesh->GetPoint(i, &nodes[3 * std::size_t(i)]);
    displacement->GetTuple(i, &displacements[3 * std::size_t(i)]);
  }
  const std::vector<double> sigma =
    nodalDisplacementUncertainty(nodes, displacements, evidence, displacementUncertaintyModelFrom(context.configuration()));
  for (vtkIdType i = 0; i < mesh->GetNumberOfPoints(); ++i) uncertainty->SetComponent(i, 0, sigma[std::size_t(i)]);
  context.products().writeModel(mesh, meshFile);
  return added;
}

struct WarpedPrior {
  LabelImage::Pointer labels; ///< the preoperative labels warped onto the intraoperative grid by the solve
  MaskImage::Pointer moved;   ///< within the reach of where the solve moved the tissue by more than MovedMm
};
/// Where the first solve stopped short (fluid taken for brain), it moved nothing at all; the
/// corrections lie next to the tissue it did move, within about the shift itself (the reach).
constexpr double MovedMm = 1.0;

/// The preoperative labels warped onto the intraoperative grid by the solved mesh.
/// The solved mesh (with its Displacement) and the rigid transform, as the earlier stages wrote them.
struct SolvedMesh {
  fs::path meshFile;
  vtkSmartPointer<vtkUnstructuredGrid> mesh;
  SpatialTransform::Pointer rigid;
};

SolvedMesh solvedMeshAndRigid(RunContext& context)
{
  SolvedMesh solved{context.output("mesh.vtu"), nullptr, nullptr};
  const fs::path rigidFile = context.output("rigid_intraop_to_preop.tfm");
  solved.mesh = vtkUnstructuredGrid::SafeDownCast(context.products().readModel(solved.meshFile));
  if (!solved.mesh) throw InputError(solved.meshFile.string() + ": not a tetrahedral mesh (vtkUnstructuredGrid)");
  if (!solved.mesh->GetPointData()->GetArray("Displacement")) {
    throw InputError(solved.meshFile.string() + ": no Displacement; run `brainshift simulate` on this output folder first");
  }
  solved.rigid = readTransform(rigidFile);
  if (!isLinearTransform(solved.rigid)) throw InputError(rigidFile.string() + ": not a rigid transform");
  return solved;
}

WarpedPrior labelsWarpedBySolve(RunContext& context, double reachMm)
{
  const SolvedMesh solved = solvedMeshAndRigid(context);
  const DeformationField deformation = intraopToPreopField(solved.mesh, *solved.rigid, ImageGeometry::of(&context.intraopImage("refine")),
                                                           DeformationFieldParameters{}, solved.meshFile.string());
  return {warpLabelVolume(context.preopLabels("refine"), *deformation.field),
          reachMm > 0 ? regionMovedBySolve(*deformation.field, *solved.rigid, MovedMm, reachMm) : nullptr};
}

/// The passes to run: the configured number, or ("auto") one where the first classification
/// found this scan's fluid brighter than its parenchyma, none elsewhere; and why.
std::pair<unsigned, std::string> refinementPasses(RunContext& context)
{
  const std::optional<unsigned> configured = context.configuration().classificationRefinementPasses;
  if (configured) return {*configured, "configured"};
  // What the first classification learned of this scan's contrast (its prototypes' medians), as
  // ScanContrast::fluidBrighterThanParenchyma decides it.
  const nlohmann::json classify = context.report().stageOrEmpty("classify");
  const nlohmann::json contrast = classify.value("contrast", nlohmann::json::object());
  const bool known = contrast.contains("fluid_median") && contrast["fluid_median"].is_number() &&
                     contrast.contains("parenchyma_median") && contrast["parenchyma_median"].is_number();
  const bool fluidBright = known && contrast["fluid_median"].get<double>() > contrast["parenchyma_median"].get<double>();
  return fluidBright ? std::pair<unsigned, std::string>{1, "auto: the scan's fluid is brighter than its parenchyma"}
                     : std::pair<unsigned, std::string>{0, "auto: the scan's fluid is darker than its parenchyma"};
}

void requireEarlierStages(RunContext& context)
{
  for (const auto& [needed, stage] : {std::pair<const char*, const char*>{"rigid_intraop_to_preop.tfm", "rigid"},
                                      {"intraop_labels.nii.gz", "classify"}, {"mesh.vtu", "mesh"},
                                      {"brain_surface.vtp", "surface"}}) {
    std::error_code ec;
    if (!fs::exists(context.output(needed), ec)) {
      throw InputError(context.output(needed).string() + ": not found; run `brainshift " + stage + "` (and the stages after it) on this output folder first");
    }
  }
}

/// What the classify stage's entry says of the tumour: resected or not, and what decided it
/// ("image": its look through the rigid prior; else the user, an earlier scan, or the look where a
/// solve put it). Empty without a decision (no tumour).
struct ClassifiedTumour {
  bool resected = false;
  std::string decidedBy;
};

std::optional<ClassifiedTumour> classifiedTumourOf(const nlohmann::json& classify)
{
  if (!classify.contains("tumour_resected") || !classify["tumour_resected"].is_boolean()) return std::nullopt;
  const nlohmann::json evidence = classify.value("tumour_evidence", nlohmann::json());
  return ClassifiedTumour{classify["tumour_resected"].get<bool>(),
                          evidence.is_object() ? evidence.value("decided_by", std::string()) : std::string()};
}

/// What the first pass found, which the refine passes keep: its classification where the solve
/// moved nothing (the anchor), its tumour decision, and what it did once for the whole scan (the
/// preoperative boundary's source and time, the worker's preparation), said again in the stages'
/// entries each pass rewrites.
struct FirstPass {
  LabelImage::Pointer anchor;
  std::optional<RunContext::HeldTumourDecision> tumourDecision;
  nlohmann::json surface, simulate;

  explicit FirstPass(RunContext& context)
  {
    surface = context.report().stageOrEmpty("surface");
    simulate = context.report().stageOrEmpty("simulate");
    takeClassification(context);
  }
  /// The classification the passes keep: the first's, or the tumour decision pass's.
  void takeClassification(RunContext& context)
  {
    anchor = context.products().readLabelVolume(context.output("intraop_labels.nii.gz"));
    tumourDecision.reset();
    if (const std::optional<ClassifiedTumour> tumour = classifiedTumourOf(context.report().stageOrEmpty("classify"))) {
      const std::string& by = tumour->decidedBy;
      tumourDecision = RunContext::HeldTumourDecision{tumour->resected,
                                                      by == "image" || by.empty() ? "the first classification (through the rigid prior)" : by};
    }
  }
  void restateIn(RunReport& report) const
  {
    nlohmann::json surfaceNow = report.stage("surface");
    for (const char* key : {"preop_boundary_from", "preop_boundary_seconds", "preop_boundary_made_ahead_seconds"}) {
      if (surface.contains(key)) surfaceNow[key] = surface[key];
    }
    report.setStage("surface", surfaceNow);
    nlohmann::json simulateNow = report.stage("simulate");
    if (simulate.value("worker_prepared", false)) simulateNow["worker_prepared"] = true;
    report.setStage("simulate", simulateNow);
  }
};

struct PassOutcome {
  DisplacementChange change;
  std::size_t disagreementNodes = 0;
  nlohmann::json entry;
};

/// One pass: the labels warped by the last solve as the prior, then classify, surface and simulate
/// again; the imposed surface's change, into the confidence map too.
PassOutcome runRefinePass(RunContext& context, unsigned pass, const FirstPass& first)
{
  Stopwatch passClock;
  const double reachMm = context.configuration().classificationRefinementReachMm;
  const auto before = imposedDisplacements(context, context.output("brain_surface.vtp"));
  const WarpedPrior prior = labelsWarpedBySolve(context, reachMm);
  context.setWarpedPrior(prior.labels, int(pass), reachMm > 0 ? prior.moved : nullptr, first.anchor);
  context.holdTumourDecision(first.tumourDecision);
  const double priorSeconds = passClock.seconds();
  runClassifyStage(context);
  runSurfaceStage(context);
  runSimulateStage(context);
  first.restateIn(context.report());
  const auto after = imposedDisplacements(context, context.output("brain_surface.vtp"));
  PassOutcome outcome;
  outcome.change = changeBetween(before, after);
  outcome.disagreementNodes = addPassDisagreementToUncertainty(context, before, after);
  const nlohmann::json& classify = context.report().stage("classify");
  outcome.entry = {{"pass", pass},
                   {"wall_seconds", passClock.seconds()},
                   {"prior_seconds", priorSeconds},
                   {"classify_seconds", classify["wall_seconds"]},
                   {"surface_seconds", context.report().stage("surface")["wall_seconds"]},
                   {"simulate_seconds", context.report().stage("simulate")["wall_seconds"]},
                   {"tumour_resected", classify["tumour_resected"]},
                   {"imposed_nodes", context.report().stage("surface")["imposed_nodes"]},
                   {"mean_change_mm", outcome.change.meanMm},
                   {"max_change_mm", outcome.change.maxMm},
                   {"compared_nodes", outcome.change.nodes}};
  context.say("refine pass %u: the imposed surface moved %.2f mm mean (%.2f max), %.2f s\n", pass, outcome.change.meanMm,
              outcome.change.maxMm, passClock.seconds());
  return outcome;
}

double numberOr(const nlohmann::json& object, const char* key, double otherwise)
{
  return object.is_object() && object.contains(key) && object[key].is_number() ? object[key].get<double>() : otherwise;
}

/// Whether any tetrahedron of `mesh` has this label (cell array "Label").
bool meshHolds(vtkUnstructuredGrid* mesh, LabelPixel label)
{
  vtkDataArray* labels = mesh->GetCellData()->GetArray("Label");
  for (vtkIdType c = 0; labels && c < labels->GetNumberOfTuples(); ++c) {
    if (std::lround(labels->GetComponent(c, 0)) == long(label)) return true;
  }
  return false;
}

/// Where `solved` puts the tumour, when the first classification decided on it by the image (its
/// place through the rigid prior): its voxels' intensities on the classification's scale, voting as
/// its prototypes did. Under a large shift that place holds what sank into it: the parenchyma over
/// a cavity (found in place), or the gap's fluid over a tumour near the cortex that sank with the
/// brain (found resected).
TumourSecondLook lookWhereSolved(RunContext& context, const SolvedMesh& solved)
{
  Stopwatch clock;
  TumourSecondLook check;
  const nlohmann::json classify = context.report().stageOrEmpty("classify");
  const nlohmann::json evidence = classify.value("tumour_evidence", nlohmann::json()); // the first look's
  const std::optional<ClassifiedTumour> tumour = classifiedTumourOf(classify);
  if (!tumour || tumour->decidedBy != "image" || !context.configuration().classificationTumourSecondLook) return check;
  const bool firstResected = tumour->resected;
  auto notChecked = [&](const std::string& why) {
    check.entry = {{"checked", false}, {"why_not", why}};
    return check;
  };
  if (context.configuration().classificationBiasCorrection) {
    return notChecked("the classification's intensities were bias-corrected (N4): the scan itself is on another scale");
  }
  const nlohmann::json contrastEntry = classify.value("contrast", nlohmann::json::object());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const IntensityScale scale{numberOr(contrastEntry, "scale_low", nan), numberOr(contrastEntry, "scale_high", nan)};
  if (!std::isfinite(scale.low) || !std::isfinite(scale.high)) return notChecked("the classification's report gives no intensity scale");
  ScanContrast contrast;
  contrast.air = numberOr(contrastEntry, "air_median", nan);
  contrast.fluid = numberOr(contrastEntry, "fluid_median", nan);
  contrast.parenchyma = numberOr(contrastEntry, "parenchyma_median", nan);
  constexpr LabelPixel tumourLabel = 4; // ../shared/CONTRACT.md
  if (!meshHolds(solved.mesh, tumourLabel)) return notChecked("the mesh holds no tumour (mesh.labels)");
  const ScalarImage& intraop = context.intraopImage("refine");
  const MaskImage::Pointer where =
    voxelsOfDeformedTissue(solved.mesh, tumourLabel, *solved.rigid, ImageGeometry::of(&intraop), solved.meshFile.string());
  std::vector<float> intensities;
  const unsigned char* m = where->GetBufferPointer();
  const float* v = intraop.GetBufferPointer();
  for (std::size_t i = 0, n = ImageGeometry::of(&intraop).numberOfVoxels(); i < n; ++i) {
    if (m[i]) intensities.push_back(scale.of(v[i]));
  }
  constexpr std::size_t fewestVoxels = 20;
  if (intensities.size() < fewestVoxels) return notChecked("the tumour lies outside the scan where the solve put it");
  const TumourResectionEvidence whereSolved =
    tumourResectionEvidenceOf(intensities, contrast, numberOr(evidence, "preop_relative", nan), TumourResection::Auto);
  const bool resected = firstResected ? !tumourShownInPlaceWhereSolved(whereSolved) : resectionShownWhereSolved(whereSolved);
  if (resected != firstResected) check.overturnedTo = resected;
  check.entry = {{"checked", true},
                 {"resected", resected},
                 {"first_look_resected", firstResected},
                 {"overturned", resected != firstResected},
                 {"evidence", tumourEvidenceJson(whereSolved)},
                 {"seconds", clock.seconds()}};
  char line[400];
  if (check.overturnedTo && resected) {
    std::snprintf(line, sizeof(line), "refine: where the first solve put the tumour, %.0f %% of it looks like fluid or air (%.0f %% like air): "
                  "resected, not in place as its place through the rigid prior said; classified again\n",
                  100 * whereSolved.fluidLikeShare, 100 * whereSolved.airLikeShare);
    context.say("%s", line);
  } else if (check.overturnedTo) {
    std::snprintf(line, sizeof(line), "refine: where the first solve put the tumour, %.0f %% of it looks like tissue, %.0f %% like fluid or "
                  "air (%.0f %% like air): in place, not resected as its place through the rigid prior said (the tumour sank with "
                  "the brain); classified again\n", 100 * (whereSolved.tumourLikeShare + whereSolved.parenchymaLikeShare),
                  100 * whereSolved.fluidLikeShare, 100 * whereSolved.airLikeShare);
    context.say("%s", line);
  } else if (!firstResected && decideTumourResection(whereSolved, TumourResection::Auto)) {
    std::snprintf(line, sizeof(line), "refine: the tumour's resection is uncertain: where the first solve put it, %.0f %% of it looks like "
                  "fluid but %.0f %% like air, as a cystic or necrotic tumour in place would; kept in place "
                  "(--tumour-resected yes if it was resected)", 100 * whereSolved.fluidLikeShare, 100 * whereSolved.airLikeShare);
    check.warning = line;
  }
  return check;
}

/// The scan classified again with the tumour decided where the first solve put it, and the
/// surface fitted and solved again on it. A resected tumour's prior stays the rigid one (its
/// voxels become background, wherever its prototypes came from); a tumour in place is classified
/// on the labels warped by the first solve, which put it where it sank (through the rigid prior its
/// prototypes would be the gap's fluid that fills its old place), and, as in a refine pass, only
/// where that solve moved the tissue: elsewhere the first classification (`firstLabels`) stays.
/// The warped prior's pass number 0 tells the classify stage's report that it is this pass.
void runTumourDecisionPass(RunContext& context, bool resected, const LabelImage::Pointer& firstLabels)
{
  struct Held { // cleared however the pass ends
    RunContext& context;
    ~Held()
    {
      context.holdTumourDecision(std::nullopt);
      context.setRepeatPass(false);
      context.setWarpedPrior(nullptr, 0);
    }
  } held{context};
  if (!resected) {
    const double reachMm = context.configuration().classificationRefinementReachMm;
    const WarpedPrior prior = labelsWarpedBySolve(context, reachMm);
    context.setWarpedPrior(prior.labels, 0, reachMm > 0 ? prior.moved : nullptr, firstLabels);
  }
  context.holdTumourDecision(RunContext::HeldTumourDecision{resected, "the tumour where the first solve put it"});
  context.setRepeatPass(true);
  runClassifyStage(context);
  runSurfaceStage(context);
  runSimulateStage(context);
}

} // namespace

bool secondLookOverturnsTumourDecision(RunContext& context, vtkUnstructuredGrid* firstSolve, const std::string& meshName)
{
  if (context.repeatPass() || !context.wholePipeline()) return false;
  const fs::path rigidFile = context.output("rigid_intraop_to_preop.tfm");
  SolvedMesh solved{meshName, firstSolve, readTransform(rigidFile)};
  if (!isLinearTransform(solved.rigid)) throw InputError(rigidFile.string() + ": not a rigid transform");
  TumourSecondLook look = lookWhereSolved(context, solved);
  // Not overturned here: the refine stage looks again where the solve with the block matches puts
  // the tumour (more exactly placed: on the small rf15 case this look saw 30 % of it like fluid,
  // that one 35 %, the vote's bound).
  if (!look.overturnedTo) return false;
  look.entry["on"] = "the surface's solve, before the block matches";
  context.keepTumourSecondLook(std::move(look));
  return true;
}

void runRefineStage(RunContext& context)
{
  Stopwatch clock;
  const auto [maximumPasses, passesFrom] = refinementPasses(context);
  const double tolerance = context.configuration().classificationRefinementToleranceMm;
  nlohmann::json passes = nlohmann::json::array();
  bool settled = false;
  std::size_t disagreementNodes = 0; // the last pass's, in the confidence map
  requireEarlierStages(context);
  FirstPass first(context);
  // The simulate stage looked already when it solved first (and left its block matches to the
  // pass that follows); else the look is on the solve as written.
  std::optional<TumourSecondLook> looked = context.takeTumourSecondLook();
  const TumourSecondLook tumour = looked ? std::move(*looked) : lookWhereSolved(context, solvedMeshAndRigid(context));
  if (!tumour.warning.empty()) context.report().addWarning(tumour.warning);
  nlohmann::json tumourEntry = tumour.entry;
  if (tumour.overturnedTo) {
    Stopwatch decisionClock;
    runTumourDecisionPass(context, *tumour.overturnedTo, first.anchor);
    if (!*tumour.overturnedTo) {
      context.report().withdrawWarnings(TumourLooksResectedWarning);
      context.report().addWarning("refine: the tumour looked resected through the rigid prior, but where the first solve put it, "
                                  "it looks in place (no cavity's air, hardly any fluid): kept in place; --tumour-resected yes if it "
                                  "was resected");
    }
    first.restateIn(context.report());
    first.takeClassification(context);
    tumourEntry["decision_pass_seconds"] = decisionClock.seconds();
    context.report().save();
  }
  try {
    for (unsigned pass = 1; pass <= maximumPasses && !settled; ++pass) {
      const PassOutcome outcome = runRefinePass(context, pass, first);
      settled = outcome.change.meanMm < tolerance;
      disagreementNodes = outcome.disagreementNodes;
      passes.push_back(outcome.entry);
      context.report().save();
    }
  } catch (...) {
    context.setWarpedPrior(nullptr, 0);
    context.holdTumourDecision(std::nullopt);
    throw;
  }
  context.setWarpedPrior(nullptr, 0);
  context.holdTumourDecision(std::nullopt);
  context.report().setStage("refine", {{"wall_seconds", clock.seconds()},
                                       {"passes", passes.size()},
                                       {"maximum_passes", maximumPasses},
                                       {"passes_from", passesFrom},
                                       {"uncertainty_disagreement_nodes", disagreementNodes},
                                       {"tolerance_mm", tolerance},
                                       {"settled", settled || maximumPasses == 0},
                                       {"tumour_where_solved", tumourEntry},
                                       {"per_pass", passes}});
  if (!settled && maximumPasses > 0) {
    char warning[160];
    std::snprintf(warning, sizeof(warning), "refine: the brain boundary still moved %.2f mm mean in the last of %u passes",
                  passes.back()["mean_change_mm"].get<double>(), maximumPasses);
    context.report().addWarning(warning);
  }
}

} // namespace brainshift
