// The stages as the command line runs them: inputs from the run context, the stage's logic, its
// files in the output folder, its entry in report.json.
#include "ActiveSurfaceLogic.h"
#include "DeformationField.h"
#include "NodalFieldRasterisation.h"
#include "NonrigidUpdateTrust.h"
#include "ModelNode.h"
#include "SceneIO.h"
#include "TransformNode.h"
#include "VolumeNodes.h"

#include <itkCompositeTransform.h>
#include <itkIdentityTransform.h>
#include <itkImageRegionConstIteratorWithIndex.h>

#include <tuple>
#include <type_traits>
#include "BiomechanicalModel.h"
#include "BrainShiftErrors.h"
#include "FiniteElementSolver.h"
#include "ImageMatchingSolve.h"
#include "ParallelRanges.h"
#include "PreparationAhead.h"
#include "LabelMapMesher.h"
#include "ModelIO.h"
#include "RigidRegistrationLogic.h"
#include "UpdateFocus.h"
#include "UpdatePipeline.h"
#include "TissueClassificationLogic.h"
#include "TransformIO.h"
#include "VolumeIO.h"
#include "WarpedPriorRefinement.h"

#include <cstdio>
#include <future>
#include <numeric>
#include <optional>

#include <vtkDoubleArray.h>
#include <vtkPointData.h>

namespace brainshift {
namespace fs = std::filesystem;

namespace {
nlohmann::json finiteOrNull(double value) { return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr); }
} // namespace

void runRigidStage(RunContext& context)
{
  Stopwatch clock;
  RigidRegistrationParameters parameters = rigidRegistrationParametersFrom(context.configuration());
  parameters.cancel = context.cancelFlag();
  // A later scan starts from the previous scan's alignment instead of the multi-start search.
  const std::optional<fs::path> previousRigid = context.previousFile("rigid_intraop_to_preop.tfm");
  if (previousRigid) {
    const SpatialTransform::Pointer start = readTransform(*previousRigid);
    if (!isLinearTransform(start)) throw InputError(previousRigid->string() + ": not a rigid transform");
    parameters.initialIntraopToPreop = start;
  }
  if (SerialScanSession* session = context.session()) { // the preoperative side once per session
    if (!session->rigidMoving) {
      session->rigidMoving = prepareRigidMoving(context.preopImage("rigid"), context.preopLabelsIfGiven(), parameters);
    }
    parameters.preparedMoving = session->rigidMoving;
  }
  const RigidRegistrationResult result = registerRigidly(context.intraopImage("rigid"), context.preopImage("rigid"),
                                                         context.preopLabelsIfGiven(), parameters);
  const double seconds = clock.seconds();
  nlohmann::json entry = {{"wall_seconds", seconds},
                          {"metric_value", result.metricValue},
                          {"iterations", std::accumulate(result.iterationsPerLevel.begin(), result.iterationsPerLevel.end(), 0u)},
                          {"iterations_per_level", result.iterationsPerLevel},
                          {"metric_work_units", result.metricWorkUnits},
                          {"normalized_mutual_information", result.normalizedMutualInformation},
                          // What these images share at wrong poses (15 mm, 15 degrees off): the trust
                          // test's baseline, whatever the contrasts; null when no displaced pose overlaps.
                          {"displaced_normalized_mutual_information", finiteOrNull(result.displacedNormalizedMutualInformation)},
                          {"displaced_normalized_mutual_information_mean", finiteOrNull(result.displacedNormalizedMutualInformationMean)},
                          {"displaced_poses_compared", result.displacedPosesCompared},
                          {"normalized_mutual_information_gain", finiteOrNull(result.normalizedMutualInformationGain)},
                          {"overlap", result.overlap},
                          {"rotation_degrees", result.rotationDegrees},
                          {"translation_mm", result.translationMm},
                          {"starts_scored", result.startsScored},
                          {"winning_start_degrees", result.winningStartDegrees},
                          {"trustworthy", result.trustworthy}};
  if (previousRigid) entry["initialised_from"] = previousRigid->string();
  if (!result.trustworthy) entry["failure"] = result.failureReason;
  context.report().setStage("rigid", entry);
  context.report().addWarnings(result.warnings);
  if (!result.trustworthy) {
    context.report().save();
    throw MethodError("rigid registration cannot be trusted: " + result.failureReason +
                      "; rigid_intraop_to_preop.tfm not written");
  }
  writeTransform(result.intraopToPreop, context.output("rigid_intraop_to_preop.tfm"));
  context.say("rigid: rotation %.2f degrees, translation %.2f mm, NMI %.3f (%.1f times as far above 1 as 15 mm or degrees off), "
              "overlap %.2f, %.2f s\n",
              result.rotationDegrees, result.translationMm, result.normalizedMutualInformation, result.normalizedMutualInformationGain,
              result.overlap, seconds);
}

} // namespace brainshift

namespace brainshift {

nlohmann::json tumourEvidenceJson(const TumourResectionEvidence& e)
{
  if (e.decidedBy.empty()) return nullptr;
  auto finite = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return {{"decided_by", e.decidedBy},
          {"tumour_median", finite(e.tumourMedian)},
          {"fluid_median", finite(e.fluidMedian)},
          {"air_median", finite(e.airMedian)},
          {"parenchyma_median", finite(e.parenchymaMedian)},
          {"intraop_relative", finite(e.intraopRelative)},
          {"preop_relative", finite(e.preopRelative)},
          {"fluid_like_share", e.fluidLikeShare},
          {"air_like_share", e.airLikeShare},
          {"tumour_like_share", e.tumourLikeShare},
          {"parenchyma_like_share", e.parenchymaLikeShare},
          {"voxels", e.voxels}};
}

namespace {

/// A partial field of view (a slab around the craniotomy) may miss a whole tissue, e.g. the
/// ventricles under a superficial craniotomy: no prototypes of it could be chosen. The tissues
/// inside the brain (labels above parenchyma, 2) of which less than `minimumMl` of the aligned
/// preoperative labels lie inside the intraoperative image are classified as parenchyma: a copy
/// of the labels with them so relabelled, null when every tissue is seen.
LabelImage::Pointer labelsSeenByTheScan(const LabelImage& preop, const SpatialTransform& rigid, const ScalarImage& intraop,
                                        std::vector<std::string>& warnings, double minimumMl = 2.0)
{
  const SpatialTransform::InverseTransformBasePointer preopToIntraop = rigid.GetInverseTransform();
  if (!preopToIntraop) return nullptr;
  constexpr LabelPixel parenchyma = 2;
  std::map<LabelPixel, std::size_t> present, inside;
  itk::ImageRegionConstIteratorWithIndex<LabelImage> it(&preop, preop.GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    if (it.Get() <= parenchyma) continue;
    ++present[it.Get()];
    PhysicalPoint x;
    preop.TransformIndexToPhysicalPoint(it.GetIndex(), x);
    itk::ContinuousIndex<double, 3> index;
    if (intraop.TransformPhysicalPointToContinuousIndex(preopToIntraop->TransformPoint(x), index)) ++inside[it.Get()];
  }
  const double voxelMl = preop.GetSpacing()[0] * preop.GetSpacing()[1] * preop.GetSpacing()[2] / 1000.0;
  std::set<LabelPixel> unseen;
  for (const auto& [label, count] : present) {
    const double insideMl = double(inside[label]) * voxelMl;
    if (insideMl >= minimumMl) continue;
    unseen.insert(label);
    char line[256];
    std::snprintf(line, sizeof(line), "classify: %s (label %d) lies outside the intraoperative field of view (%.1f of %.1f ml "
                  "inside); classified as parenchyma", tissueName(label).c_str(), int(label), insideMl, double(count) * voxelMl);
    warnings.push_back(line);
  }
  if (unseen.empty()) return nullptr;
  auto copy = LabelImage::New();
  copy->CopyInformation(&preop);
  copy->SetRegions(preop.GetLargestPossibleRegion());
  copy->Allocate();
  const LabelPixel* from = preop.GetBufferPointer();
  LabelPixel* to = copy->GetBufferPointer();
  for (std::size_t i = 0, n = preop.GetLargestPossibleRegion().GetNumberOfPixels(); i < n; ++i) {
    to[i] = unseen.count(from[i]) ? parenchyma : from[i];
  }
  return copy;
}

/// The spatial prior: the preoperative labels through the rigid transform (the tissues the scan
/// shows), or (refine) the preoperative labels warped by the last solve, on the intraoperative grid.
TissueClassificationResult classifyWithPrior(RunContext& context, const SpatialTransform& rigid,
                                             const std::optional<std::vector<TissuePrototype>>& prototypes,
                                             TissueClassificationParameters parameters)
{
  const LabelImage* prior = context.warpedPrior();
  if (prior) {
    const auto identity = itk::IdentityTransform<double, 3>::New();
    return classifyTissues(context.intraopImage("classify"), *prior, *identity, prototypes, parameters);
  }
  std::vector<std::string> fieldOfViewWarnings;
  const LabelImage::Pointer seen =
    labelsSeenByTheScan(context.preopLabels("classify"), rigid, context.intraopImage("classify"), fieldOfViewWarnings);
  context.report().addWarnings(fieldOfViewWarnings);
  if (!seen) { // the preoperative maps once per session, or per run (a repeated pass)
    SerialScanSession& kept = context.kept();
    if (!kept.tissueMaps) kept.tissueMaps = preparePreoperativeTissueMaps(context.preopLabels("classify"));
    parameters.preoperativeMaps = kept.tissueMaps;
  }
  return classifyTissues(context.intraopImage("classify"), seen ? *seen : context.preopLabels("classify"), rigid, prototypes, parameters);
}

/// What the prototypes learned of this scan's contrast (0-100 scale), its fluid's side, and the
/// scale (the intraoperative values at 0 and 100).
nlohmann::json scanContrastJson(const ScanContrast& c, const IntensityScale& scale)
{
  auto finite = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  return {{"air_median", finite(c.air)},
          {"fluid_median", finite(c.fluid)},
          {"parenchyma_median", finite(c.parenchyma)},
          {"fluid", c.fluidBrighterThanParenchyma() ? "brighter than the parenchyma" : "darker than the parenchyma"},
          {"scale_low", scale.low},
          {"scale_high", scale.high}};
}

/// Whether the previous scan's classify entry holds `key` as true (false without a previous scan,
/// or for an entry of another shape).
bool previousClassifySaid(const RunContext& context, const char* key)
{
  const nlohmann::json& previous = context.previousReport();
  if (!previous.contains("stages") || !previous["stages"].contains("classify")) return false;
  const nlohmann::json& classify = previous["stages"]["classify"];
  return classify.is_object() && classify.contains(key) && classify[key].is_boolean() && classify[key].get<bool>();
}

/// The tumour decision the classification takes instead of its own, when it would decide by the
/// image: the refine stage's (held in the context), else a resection an earlier scan of this case
/// found (a tumour resected stays resected; its cavity at a later, larger shift may sit where
/// tissue sank, the decision's blind spot through the rigid prior).
std::optional<RunContext::HeldTumourDecision> tumourDecisionToHold(const RunContext& context, const TissueClassificationParameters& parameters)
{
  if (parameters.tumourResection != TumourResection::Auto) return std::nullopt;
  if (context.heldTumourDecision()) return context.heldTumourDecision();
  if (previousClassifySaid(context, "tumour_resected")) return RunContext::HeldTumourDecision{true, "an earlier scan of this case (resected there)"};
  return std::nullopt;
}
} // namespace

void runClassifyStage(RunContext& context)
{
  Stopwatch clock;
  const fs::path rigidFile = context.output("rigid_intraop_to_preop.tfm");
  std::error_code ec;
  if (!fs::exists(rigidFile, ec)) {
    throw InputError(rigidFile.string() + ": no rigid transform; run `brainshift rigid` on this output folder first");
  }
  const SpatialTransform::Pointer rigid = readTransform(rigidFile);
  if (!isLinearTransform(rigid)) throw InputError(rigidFile.string() + ": not a rigid transform");
  std::optional<std::vector<TissuePrototype>> prototypes;
  // Picked once, reused for later scans: the given ones, else those the previous scan was given
  // (picked by a user, carried from scan to scan). Prototypes the previous scan chose by itself
  // are chosen afresh: they come from the aligned preoperative labels at no cost, and reused on a
  // scan where the brain has moved further they made the result worse (TRE 0.95 against 0.60 mm
  // on the built-in case's later scan).
  std::optional<fs::path> prototypesFile;
  if (!context.options().prototypes.empty()) {
    prototypesFile = context.options().prototypes;
  } else {
    if (previousClassifySaid(context, "prototypes_given")) prototypesFile = context.previousFile("classification_prototypes.json");
  }
  if (prototypesFile) prototypes = readPrototypes(*prototypesFile);
  const Configuration& configuration = context.configuration();
  TissueClassificationParameters parameters = classificationParametersFrom(configuration);
  parameters.cancel = context.cancelFlag();
  if (!context.options().preopImage.empty()) {
    takePreoperativeImage(parameters, context.preopImage("classify"), context.preopLabels("classify"), *rigid);
  }
  const LabelImage* prior = context.warpedPrior();
  const std::optional<RunContext::HeldTumourDecision> held = tumourDecisionToHold(context, parameters);
  if (held) parameters.tumourResection = held->resected ? TumourResection::Resected : TumourResection::InPlace;
  const TissueClassificationResult result = classifyWithPrior(context, *rigid, prototypes, parameters);
  nlohmann::json tumourEvidence = tumourEvidenceJson(result.tumourEvidence);
  if (held && !tumourEvidence.is_null()) tumourEvidence["decided_by"] = held->decidedBy;
  // refine: the first classification stays where the solve moved nothing.
  const std::size_t relabelled = prior && context.movedByPrior() && context.anchorLabels()
                                   ? keepAnchorOutside(*result.labels, *context.anchorLabels(), *context.movedByPrior())
                                   : 0;
  context.products().writeLabelVolume(result.labels, context.output("intraop_labels.nii.gz"));
  // Recorded for the next scan of the same case (intraoperative scanner frame).
  writePrototypes(result.prototypes, context.output("classification_prototypes.json"));
  nlohmann::json perClass = nlohmann::json::object();
  std::size_t total = 0;
  for (const auto& [label, count] : result.prototypesPerClass) {
    perClass[tissueName(label)] = count;
    total += count;
  }
  const double seconds = clock.seconds();
  context.report().setStage("classify", {{"wall_seconds", seconds},
                                         {"voxels", result.voxels},
                                         {"prototypes", total},
                                         {"prototypes_per_class", perClass},
                                         {"prototypes_given", prototypes.has_value()},
                                         {"prototypes_from", prototypesFile ? prototypesFile->string() : std::string()},
                                         {"k", parameters.k},
                                         {"seed", parameters.seed},
                                         {"tumour_resected", result.tumourResected},
                                         {"tumour_evidence", tumourEvidence},
                                         {"contrast", scanContrastJson(result.contrast, result.intensityScale)},
                                         {"relabelled_where_moved", relabelled},
                                         {"fluid_joined_to_gaps_ml", result.fluidJoinedToGapsMl},
                                         {"prior", !prior ? std::string("preoperative labels through the rigid transform")
                                                   : context.warpedPriorPass() > 0
                                                     ? "preoperative labels warped by refine pass " + std::to_string(context.warpedPriorPass())
                                                     : std::string("preoperative labels warped by the first solve (the tumour's second look)")},
                                         {"feature_seconds", result.featureSeconds},
                                         {"knn_seconds", result.knnSeconds},
                                         {"knn_queries", result.knnQueries},
                                         {"cleanup_seconds", result.cleanupSeconds}});
  context.report().addWarnings(result.warnings);
  context.say("classify: %zu voxels, %zu prototypes, k-NN %.2f s, %.2f s%s\n", result.voxels, total, result.knnSeconds,
              seconds, result.tumourResected ? ", tumour resected" : "");
}

} // namespace brainshift

namespace brainshift {

namespace {
/// A watch session's solve: its served worker when it was prepared for this mesh, materials and
/// solver options (the scan's fixed nodes are eliminated anew), else a worker prepared now.
/// Iterative by default (solverOptionsForRepeatedSolves).
FiniteElementResult solveInSession(SerialScanSession& session, FiniteElementJob job, const FiniteElementRunOptions& options,
                                   bool& prepared)
{
  job.solverOptions = solverOptionsForRepeatedSolves(job.solverOptions);
  auto sameProblem = [&job](const FiniteElementJob& other) {
    if (other.nodes != job.nodes || other.tetrahedra != job.tetrahedra || other.materialOfTetrahedron != job.materialOfTetrahedron ||
        other.solverOptions != job.solverOptions || other.materials.size() != job.materials.size()) {
      return false;
    }
    for (std::size_t m = 0; m < job.materials.size(); ++m) {
      if (other.materials[m].youngsModulus != job.materials[m].youngsModulus ||
          other.materials[m].poissonRatio != job.materials[m].poissonRatio) {
        return false;
      }
    }
    return true;
  };
  if (session.worker && sameProblem(session.worker->preparedJob())) {
    prepared = false;
    return session.worker->solve(job.fixedNodes, job.fixedDisplacements);
  }
  session.worker.reset(); // another mesh: its worker stops
  session.worker = std::make_unique<FiniteElementSession>(job, options);
  prepared = true;
  return session.worker->solve(job.fixedDisplacements);
}
} // namespace

namespace {
/// The finite element worker's options for a stage of this context: its progress as the stage's
/// lines, its cancellation the context's. A session's served worker outlives one scan's context:
/// its progress and cancellation then go through the session (for as long as this object lives).
struct WorkerOptions {
  FiniteElementRunOptions options;
  SerialScanSession* session = nullptr;

  WorkerOptions(RunContext& context, const std::string& stage)
    : session(context.session())
  {
    options.ranks = context.configuration().ranks;
    options.worker = workerBesideExecutable();
    options.cancel = context.cancelFlag();
    options.progress = [&context, stage](const std::string& step, double) {
      if (step != "done") context.say("%s: %s\n", stage.c_str(), step.c_str());
    };
    if (!session) return;
    session->solveProgress = [&context, stage](const std::string& step) { context.say("%s: %s\n", stage.c_str(), step.c_str()); };
    options.progress = [served = session](const std::string& step, double) {
      if (step != "done" && served->solveProgress) served->solveProgress(step);
    };
    options.cancel = &session->cancelRequested;
  }
  ~WorkerOptions()
  {
    if (session) session->solveProgress = nullptr;
  }
  WorkerOptions(const WorkerOptions&) = delete;
  WorkerOptions& operator=(const WorkerOptions&) = delete;
};
} // namespace

namespace {
/// The point array "DisplacementUncertainty" (mm) of the solved mesh: the confidence of the
/// displacement from the evidence behind it (DisplacementUncertainty.h): the imposed surface nodes
/// and, when block matching ran, the kept matches and every match's misfit.
void attachUncertainty(vtkUnstructuredGrid* mesh, const FiniteElementJob& job, const FiniteElementResult& result, DisplacementEvidence& evidence,
                       const DisplacementUncertaintyModel& model)
{
  for (std::int32_t node : job.fixedNodes) {
    evidence.points.push_back({job.nodes[3 * std::size_t(node)], job.nodes[3 * std::size_t(node) + 1], job.nodes[3 * std::size_t(node) + 2]});
  }
  const std::vector<double> sigma = nodalDisplacementUncertainty(job.nodes, result.displacements, evidence, model);
  vtkNew<vtkDoubleArray> array;
  array->SetName("DisplacementUncertainty");
  array->SetNumberOfTuples(vtkIdType(sigma.size()));
  for (std::size_t i = 0; i < sigma.size(); ++i) array->SetValue(vtkIdType(i), sigma[i]);
  mesh->GetPointData()->AddArray(array);
}
} // namespace

void runSimulateStage(RunContext& context)
{
  Stopwatch clock;
  const fs::path meshFile = context.output("mesh.vtu"), surfaceFile = context.output("brain_surface.vtp");
  vtkSmartPointer<vtkUnstructuredGrid> mesh = vtkUnstructuredGrid::SafeDownCast(context.products().readModel(meshFile));
  if (!mesh) throw InputError(meshFile.string() + ": not a tetrahedral mesh (vtkUnstructuredGrid)");
  vtkSmartPointer<vtkPolyData> surface = vtkPolyData::SafeDownCast(context.products().readModel(surfaceFile));
  if (!surface) throw InputError(surfaceFile.string() + ": not a surface (vtkPolyData)");
  const Configuration& configuration = context.configuration();
  const FiniteElementJob job = finiteElementJobFromModel(mesh, surface, configuration, meshFile.string(), surfaceFile.string());
  bool served = false, prepared = false;
  FiniteElementResult result;
  // Block matching solves again with the matches: a run outside a watch session then keeps one
  // worker for both solves and for the run's later passes (partitioned and assembled once), as a
  // watch session does.
  const std::optional<std::string> matchingUnavailable =
    configuration.blockMatching.enabled ? imageMatchingUnavailable(context) : std::optional<std::string>("disabled");
  SerialScanSession* session = context.session();
  served = session != nullptr;
  const WorkerOptions worker(context, "simulate");
  const FiniteElementRunOptions& options = worker.options;
  if (!session && !matchingUnavailable) session = &context.kept();
  if (session) {
    result = solveInSession(*session, job, options, prepared);
  } else {
    result = solveWithWorker(job, options);
  }
  const FiniteElementResult surfaceOnly = result;
  DisplacementEvidence evidence;
  nlohmann::json blockMatching = {{"enabled", configuration.blockMatching.enabled}};
  if (configuration.blockMatching.enabled && matchingUnavailable) {
    blockMatching["used"] = false;
    blockMatching["reason"] = *matchingUnavailable;
    context.report().addWarning("simulate: block matching did not run (" + *matchingUnavailable + "); the solve is the surface's alone");
  } else if (configuration.blockMatching.enabled) {
    // A first solve the tumour's second look replaces (finding the tumour resected, or in place,
    // where this solve puts it, against the first classification: the refine stage classifies and
    // solves again) is the surface's alone: the pass after it matches the blocks. (Before the
    // refine stage's passes, by contrast, the first solve matches its blocks: the labels it warps
    // are their prior, and solved by the surface alone it cost the T2 scans 0.05-0.13 mm mean.)
    attachDisplacements(mesh, surfaceOnly);
    if (secondLookOverturnsTumourDecision(context, mesh, meshFile.string())) {
      const std::string why = "where the surface's solve puts the tumour overturns the classification's decision on it: the refine "
                              "stage classifies and solves again";
      blockMatching["used"] = false;
      blockMatching["reason"] = why + ", and matches the blocks there";
      context.say("simulate: block matching waits: %s\n", why.c_str());
    } else {
      const ConstrainedSolve solve = [&](const FiniteElementJob& constrained) {
        return session->worker->solve(constrained.fixedNodes, constrained.fixedDisplacements, constrained.softConstraints,
                                      constrained.rejection);
      };
      result = runImageDrivenSolve(context, mesh, job, surfaceOnly, solve, blockMatching, evidence);
    }
  }
  attachDisplacements(mesh, result);
  attachUncertainty(mesh, job, result, evidence, displacementUncertaintyModelFrom(context.configuration()));
  context.setSolveEvidence(evidence);
  context.products().writeModel(mesh, meshFile);
  context.report().setStage("simulate", {{"wall_seconds", clock.seconds()},
                                         {"served", served},
                                         {"worker_prepared", prepared},
                                         {"equations", result.equations},
                                         {"ranks", result.ranks},
                                         {"iterations", result.iterations},
                                         {"relative_residual", result.relativeResidual},
                                         {"assembly_seconds", result.assemblySeconds},
                                         {"setup_seconds", result.setupSeconds},
                                         {"solve_seconds", result.solveSeconds},
                                         {"solver", result.solver},
                                         {"partitioner", result.partitioner},
                                         {"tetrahedra_per_rank", result.tetrahedraPerRank},
                                         {"imposed_nodes", job.fixedNodes.size()},
                                         {"block_matching", blockMatching}});
  context.say("simulate: %lld equations on %d rank(s), %d iterations, residual %.1e; assembly %.2f s, setup %.2f s, solve %.2f s\n",
              static_cast<long long>(result.equations), result.ranks, result.iterations, result.relativeResidual,
              result.assemblySeconds, result.setupSeconds, result.solveSeconds);
}

namespace {
/// The configuration's surface parameters, with this run's Cancel.
ActiveSurfaceParameters surfaceParametersFor(RunContext& context)
{
  ActiveSurfaceParameters parameters = activeSurfaceParametersFrom(context.configuration());
  parameters.cancel = context.cancelFlag();
  return parameters;
}

/// The preoperative brain surface at each node's preoperative boundary (PreopBoundary), found from
/// the preoperative labels alone: the most costly part of the surface stage, which every scan then
/// reuses. Its nodes, imposed at rest, give the served worker a problem of the right shape to
/// prepare on.
void preparePreoperativeSurface(RunContext& context)
{
  Stopwatch clock;
  const fs::path meshFile = context.output("mesh.vtu");
  vtkSmartPointer<vtkUnstructuredGrid> mesh = vtkUnstructuredGrid::SafeDownCast(context.products().readModel(meshFile));
  if (!mesh) throw InputError(meshFile.string() + ": not a tetrahedral mesh (vtkUnstructuredGrid)");
  ActiveSurfaceInputNames names;
  names.mesh = meshFile.string();
  names.preopLabels = context.options().preopLabels.string();
  const PreoperativeBrainBoundary boundary =
    preoperativeBrainBoundary(mesh, context.preopLabels("prepare"), surfaceParametersFor(context), names);
  context.products().writeModel(boundary.surface, context.output("brain_surface.vtp"));
  const vtkIdType nodes = boundary.surface->GetNumberOfPoints();
  context.report().setStage("preoperative_surface", {{"wall_seconds", clock.seconds()},
                                                     {"surface_nodes", nodes},
                                                     {"imposed_nodes", nodes},
                                                     {"preop_boundary_seconds", boundary.seconds}});
  context.report().addWarnings(boundary.warnings);
  context.say("prepare: the preoperative brain boundary at %lld surface nodes, %.2f s\n", static_cast<long long>(nodes), clock.seconds());
}

/// The session's served worker, partitioned and assembled on the prepared mesh before the first
/// scan (that scan then eliminates its own fixed nodes and sets its preconditioner up).
void prepareServedWorker(RunContext& context)
{
  Stopwatch clock;
  if (!context.session()) throw std::logic_error("prepareServedWorker: not in a session");
  const fs::path meshFile = context.output("mesh.vtu"), surfaceFile = context.output("brain_surface.vtp");
  vtkSmartPointer<vtkUnstructuredGrid> mesh = vtkUnstructuredGrid::SafeDownCast(context.products().readModel(meshFile));
  vtkSmartPointer<vtkPolyData> surface = vtkPolyData::SafeDownCast(context.products().readModel(surfaceFile));
  if (!mesh || !surface) throw InputError(context.output("").string() + ": the prepared mesh or surface cannot be read");
  const FiniteElementJob job = finiteElementJobFromModel(mesh, surface, context.configuration(), meshFile.string(), surfaceFile.string());
  const WorkerOptions worker(context, "prepare");
  bool prepared = false;
  const FiniteElementResult result = solveInSession(*context.session(), job, worker.options, prepared);
  context.report().setStage("worker", {{"wall_seconds", clock.seconds()},
                                       {"prepared", prepared},
                                       {"equations", result.equations},
                                       {"ranks", result.ranks},
                                       {"partitioner", result.partitioner}});
  context.say("prepare: the finite element worker served, %lld equations on %d rank(s), %.2f s\n",
              static_cast<long long>(result.equations), result.ranks, clock.seconds());
}
} // namespace

void runPreparation(RunContext& context)
{
  const std::size_t steps = 3;
  context.stageStarts("mesh", 0, steps);
  runMeshStage(context);
  throwIfCancelled(context.cancelFlag(), "the preparation");
  context.stageStarts("surface", 1, steps);
  preparePreoperativeSurface(context);
  throwIfCancelled(context.cancelFlag(), "the preparation");
  if (context.session()) {
    context.stageStarts("simulate", 2, steps);
    prepareServedWorker(context);
  }
}

} // namespace brainshift

namespace brainshift {

void runMeshStage(RunContext& context)
{
  Stopwatch clock;
  const Configuration& configuration = context.configuration();
  MeshingParameters parameters = meshingParametersFrom(configuration);
  parameters.cancel = context.cancelFlag();
  nlohmann::json regionOfInterest = nullptr;
  if (parameters.regionOfInterest) {
    regionOfInterest = {{"center_lps", parameters.regionOfInterest->centerLps}, {"radius_mm", parameters.regionOfInterest->radiusMm}};
  }
  // A later scan of the same case (same preoperative labels, checked by register) reuses the
  // previous scan's mesh when it was made with the same settings.
  const std::optional<fs::path> previousMesh = context.previousFile("mesh.vtu");
  const nlohmann::json& previousReport = context.previousReport();
  const nlohmann::json* before = nullptr;
  if (previousMesh && previousReport.contains("stages") && previousReport["stages"].contains("mesh")) before = &previousReport["stages"]["mesh"];
  bool sameSettings = false;
  if (before) {
    try {
      sameSettings = before->value("resolution_mm", -1.0) == parameters.resolutionMm &&
                     before->value("backend", "") == configuration.meshBackend &&
                     before->value("labels", std::vector<int>{}) == parameters.labels &&
                     before->value("grading", -1.0) == parameters.gradingRate &&
                     before->value("coarsening_levels", -1) == parameters.coarseningLevels &&
                     before->value("region_of_interest", nlohmann::json()) == regionOfInterest;
    } catch (const nlohmann::json::exception&) { // an entry of another shape: mesh anew
      sameSettings = false;
    }
  }
  if (sameSettings) {
    vtkSmartPointer<vtkUnstructuredGrid> mesh = vtkUnstructuredGrid::SafeDownCast(context.products().readModel(*previousMesh));
    if (!mesh) throw InputError(previousMesh->string() + ": not a tetrahedral mesh (vtkUnstructuredGrid)");
    mesh->GetPointData()->RemoveArray("Displacement"); // the previous scan's solution
    mesh->GetPointData()->RemoveArray("DisplacementMagnitude");
    context.products().writeModel(mesh, context.output("mesh.vtu"));
    nlohmann::json entry = *before;
    entry["wall_seconds"] = clock.seconds();
    entry["reused_from"] = previousMesh->string();
    context.report().setStage("mesh", entry);
    context.say("mesh: %lld nodes, reused from the previous scan, %.2f s\n", entry.value("nodes", 0LL), clock.seconds());
    return;
  }
  // Made beside the rigid registration and the classification in this run, or made here.
  PreparationAhead* ahead = context.preparationAhead();
  LabelMapMesh madeHere;
  if (!ahead) madeHere = meshLabelMap(context.preopLabels("mesh"), parameters);
  const LabelMapMesh& result = ahead ? ahead->mesh(context.cancelFlag()) : madeHere;
  context.products().writeModel(result.mesh, context.output("mesh.vtu"));
  const MeshQuality& q = result.quality;
  nlohmann::json volumes = nlohmann::json::object(), voxels = nlohmann::json::object();
  for (const auto& [label, ml] : q.meshVolumeMl) {
    volumes[std::to_string(label)] = ml;
    voxels[std::to_string(label)] = q.voxelVolumeMl.at(label);
  }
  context.report().setStage("mesh", {{"wall_seconds", clock.seconds()},
                                     {"backend", configuration.meshBackend},
                                     {"resolution_mm", parameters.resolutionMm},
                                     {"labels", parameters.labels},
                                     {"grading", parameters.gradingRate},
                                     {"coarsening_levels", parameters.coarseningLevels},
                                     {"region_of_interest", regionOfInterest},
                                     {"nodes", q.nodes},
                                     {"tetrahedra", q.tetrahedra},
                                     {"equations", 3 * q.nodes},
                                     {"min_dihedral_degrees", q.minimumDihedralDegrees},
                                     {"max_dihedral_degrees", q.maximumDihedralDegrees},
                                     {"inverted_tetrahedra", q.invertedOrFlat},
                                     {"radius_ratio_histogram", q.radiusRatioHistogram},
                                     {"volume_ml", volumes},
                                     {"voxel_volume_ml", voxels},
                                     {"made_ahead_seconds", ahead ? nlohmann::json(ahead->meshSeconds()) : nlohmann::json()}});
  context.report().addWarnings(result.warnings);
  if (ahead) {
    context.say("mesh: %zu nodes, %zu tetrahedra, dihedral %.0f to %.0f degrees, made in %.2f s beside the rigid registration, "
                "%.2f s here\n",
                q.nodes, q.tetrahedra, q.minimumDihedralDegrees, q.maximumDihedralDegrees, ahead->meshSeconds(), clock.seconds());
  } else {
    context.say("mesh: %zu nodes, %zu tetrahedra, dihedral %.0f to %.0f degrees, %.2f s\n", q.nodes, q.tetrahedra,
                q.minimumDihedralDegrees, q.maximumDihedralDegrees, clock.seconds());
  }
}

} // namespace brainshift

namespace brainshift {

namespace {
/// The preoperative boundary the surface stage need not fit again, when one is known: this scan's
/// own in a refine pass, the previous scan's on the same mesh, or the one made beside this run's
/// rigid registration; else none (`surface` null, `from` empty).
struct KnownPreoperativeBoundary {
  vtkSmartPointer<vtkPolyData> surface;
  std::string from;
  double madeAheadSeconds = 0;
};

KnownPreoperativeBoundary knownPreoperativeBoundary(RunContext& context)
{
  KnownPreoperativeBoundary known;
  std::optional<fs::path> file = context.previousFile("brain_surface.vtp");
  const bool samePass = context.repeatPass(); // refine: this scan's own surface, same mesh
  if (samePass) file = context.output("brain_surface.vtp");
  const bool meshReused = context.report().hasStage("mesh") && context.report().stage("mesh").contains("reused_from");
  if (file && (samePass || meshReused)) {
    known.surface = vtkPolyData::SafeDownCast(context.products().readModel(*file));
    if (!known.surface) throw InputError(file->string() + ": not a surface (vtkPolyData)");
    if (!known.surface->GetPointData()->GetArray("PreopBoundary")) return {}; // an older run's: fit again
    known.from = file->string();
  } else if (PreparationAhead* ahead = context.preparationAhead(); ahead && !samePass) {
    const PreoperativeBrainBoundary& prepared = ahead->boundary(context.cancelFlag());
    known.surface = prepared.surface;
    known.from = "made beside the rigid registration";
    known.madeAheadSeconds = prepared.seconds;
    context.report().addWarnings(prepared.warnings);
  }
  return known;
}
} // namespace

void runSurfaceStage(RunContext& context)
{
  Stopwatch clock;
  const fs::path meshFile = context.output("mesh.vtu"), rigidFile = context.output("rigid_intraop_to_preop.tfm"),
                 labelsFile = context.output("intraop_labels.nii.gz");
  for (const fs::path& needed : {meshFile, rigidFile, labelsFile}) {
    std::error_code ec;
    if (!fs::exists(needed, ec)) {
      throw InputError(needed.string() + ": not found; run `brainshift " +
                       std::string(needed == meshFile ? "mesh" : needed == rigidFile ? "rigid" : "classify") +
                       "` on this output folder first");
    }
  }
  vtkSmartPointer<vtkUnstructuredGrid> mesh = vtkUnstructuredGrid::SafeDownCast(context.products().readModel(meshFile));
  if (!mesh) throw InputError(meshFile.string() + ": not a tetrahedral mesh (vtkUnstructuredGrid)");
  const SpatialTransform::Pointer rigid = readTransform(rigidFile);
  if (!isLinearTransform(rigid)) throw InputError(rigidFile.string() + ": not a rigid transform");
  const LabelImage::Pointer labels = context.products().readLabelVolume(labelsFile);
  const ActiveSurfaceParameters parameters = surfaceParametersFor(context);
  ActiveSurfaceInputNames names;
  names.mesh = meshFile.string();
  names.labels = labelsFile.string();
  names.rigid = rigidFile.string();
  names.preopLabels = context.options().preopLabels.string();
  const KnownPreoperativeBoundary known = knownPreoperativeBoundary(context);
  vtkSmartPointer<vtkPolyData> previousSurface = known.surface;
  if (previousSurface) names.previousSurface = known.from;
  const ActiveSurfaceResult result = deformBrainSurface(mesh, &context.preopLabels("surface"), *labels,
                                                        &context.intraopImage("surface"), *rigid, parameters, names, previousSurface);
  context.products().writeModel(result.surface, context.output("brain_surface.vtp"));
  context.report().setStage("surface", {{"wall_seconds", clock.seconds()},
                                        {"surface_nodes", result.surfaceNodes},
                                        {"imposed_nodes", result.imposedNodes},
                                        {"free_nodes", {{"resected_tumour", result.freeResected},
                                                        {"outside_image", result.freeOutsideImage},
                                                        {"unmatched", result.freeUnmatched}}},
                                        {"held_outside_image", result.heldOutsideImage},
                                        {"field_of_view", {{"surface_nodes_inside", result.coveredSurfaceNodes},
                                                           {"brain_ml_inside", result.coveredBrainMl},
                                                           {"brain_ml", result.meshedBrainMl}}},
                                        {"iterations", result.iterations},
                                        {"converged", result.converged},
                                        {"initial_mean_residual_mm", result.initialMeanResidualMm},
                                        {"mean_residual_mm", result.meanResidualMm},
                                        {"p95_residual_mm", result.p95ResidualMm},
                                        {"max_residual_mm", result.maxResidualMm},
                                        {"mean_displacement_mm", result.meanDisplacementMm},
                                        {"max_displacement_mm", result.maxDisplacementMm},
                                        {"image_term_nodes", result.imageTermNodes},
                                        {"expected_intensity_inside", result.expectedInsideIntensity},
                                        {"expected_intensity_outside", result.expectedOutsideIntensity},
                                        {"outside_brighter_share", result.outsideBrighterShare},
                                        {"outside_sides", result.outsideSides},
                                        {"tumour_resected", result.tumourResected},
                                        {"flipped_triangles", result.flippedTriangles},
                                        {"sinking_direction", result.sinkingDirection},
                                        {"directional_nodes", result.directionalNodes},
                                        {"unsnapped_nodes", result.unsnappedNodes},
                                        {"rest_band", {{"band_mm", parameters.restBandMm},
                                                       {"smoothing_passes", parameters.restBandSmoothingPasses},
                                                       {"held_nodes", result.restHeldNodes},
                                                       {"scaled_nodes", result.restScaledNodes},
                                                       {"local_move_median_mm", result.restLocalMoveMedianMm}}},
                                        {"residual_correction", {{"applied", parameters.residualCorrection},
                                                                 {"mean_mm", result.residualCorrectionMeanMm},
                                                                 {"max_mm", result.residualCorrectionMaxMm}}},
                                        {"boundary_offset", {{"median_normal_mm", result.boundaryOffsetNodes > 0 ? nlohmann::json(result.boundaryOffsetMm)
                                                                                                          : nlohmann::json(nullptr)},
                                                             {"nodes", result.boundaryOffsetNodes},
                                                             {"warning_beyond_mm", result.boundaryOffsetWarningMm}}},
                                        {"preop_boundary_seconds", result.preopBoundarySeconds},
                                        {"preop_boundary_from", known.from},
                                        {"preop_boundary_made_ahead_seconds", known.madeAheadSeconds},
                                        {"target_seconds", result.targetSeconds},
                                        {"iteration_seconds", result.iterationSeconds}});
  context.report().replaceWarnings("surface fit", result.warnings); // a refine pass's fit replaces the one before
  context.say("surface: %zu nodes (%zu imposed), %u iterations, residual %.2f mm mean (from %.2f), displacement up to %.1f mm, %.2f s\n",
              result.surfaceNodes, result.imposedNodes, result.iterations, result.meanResidualMm, result.initialMeanResidualMm,
              result.maxDisplacementMm, clock.seconds());
}

} // namespace brainshift

namespace brainshift {

namespace {
/// The update as a 3D Slicer scene beside its files: the intraoperative scan in the world, the
/// warped volumes on it, the preoperative image under the whole transform (Slicer warps it live),
/// the brain surface coloured by its displacement under the rigid transform (the model frame).
/// A rejected non-rigid update says so in the name of the transform that stands in for it.
/// The confidence map's name in the scene.
constexpr const char* UncertaintyMapName = DisplacementUncertaintyNodeName;

/// The confidence map on the scan: the solve's nodal "DisplacementUncertainty" rasterised in the
/// model frame (2 mm) and brought onto the intraoperative grid by the update's own field; outside
/// the brain's mesh the mapping is the rigid one, whose error is taken as OutsideMeshMm. Null when the
/// mesh has no such array (a solve from before it existed).
ScalarImage::Pointer uncertaintyOnScan(vtkUnstructuredGrid* mesh, const DisplacementFieldImage& field, const std::string& meshName,
                                       nlohmann::json& entry)
{
  constexpr float OutsideMeshMm = 0.5f;
  if (!mesh->GetPointData()->GetArray("DisplacementUncertainty")) return nullptr;
  std::vector<float> inBrain;
  const ScalarImage::Pointer onScan = nodalScalarOnGrid(mesh, "DisplacementUncertainty", field, 2.0, OutsideMeshMm, &inBrain, meshName);
  auto share = [&inBrain](float limit) {
    return inBrain.empty() ? 0.0 : double(std::lower_bound(inBrain.begin(), inBrain.end(), limit) - inBrain.begin()) / double(inBrain.size());
  };
  entry = {{"file", "displacement_uncertainty_mm.nii.gz"},
           {"outside_mesh_mm", OutsideMeshMm},
           {"median_mm", inBrain.empty() ? 0.0 : double(inBrain[inBrain.size() / 2])},
           {"p95_mm", inBrain.empty() ? 0.0 : double(inBrain[std::size_t(0.95 * double(inBrain.size() - 1))])},
           {"share_below_1mm", share(1.0f)},
           {"share_below_2mm", share(2.0f)}};
  return onScan;
}

void writeUpdateScene(RunContext& context, const std::vector<std::tuple<std::string, fs::path, ScalarImage::Pointer>>& warpedScalars,
                      const fs::path& warpedLabelsFile, const LabelImage::Pointer& warpedLabels, const SpatialTransform::Pointer& rigidTransform,
                      const SpatialTransform::Pointer& wholeTransform, vtkSmartPointer<vtkPolyData> brainSurface, bool rigidFallback)
{
  Scene scene;
  auto stored = [](auto node, const fs::path& file) {
    node->setStorageFile(fs::absolute(file));
    node->markStored();
    return node;
  };
  const RunOptions& o = context.options();
  // The data are in memory already; the nodes only point at their files.
  auto shared = [](const auto& image) { return typename std::remove_cv_t<std::remove_reference_t<decltype(image)>>::Pointer(const_cast<std::remove_cv_t<std::remove_reference_t<decltype(image)>>*>(&image)); };
  auto rigid = scene.add(stored(TransformNode::create("rigid intraop_to_preop", rigidTransform), context.output("rigid_intraop_to_preop.tfm")));
  const std::string wholeName = rigidFallback ? "intraop_to_preop (rigid fallback)" : "intraop_to_preop";
  auto whole = scene.add(stored(TransformNode::create(wholeName, wholeTransform), context.output("intraop_to_preop.h5")));
  auto intraop = scene.add(stored(ScalarVolumeNode::create("intraop image", shared(context.intraopImage("warp"))), o.intraopImage));
  intraop->setRole("intraop");
  std::string warpedImageId, firstOverlayId;
  for (const auto& [name, file, image] : warpedScalars) {
    auto node = scene.add(stored(ScalarVolumeNode::create(name, image), file));
    if (name == "warped preop image") warpedImageId = node->id();
    else if (name != UncertaintyMapName && firstOverlayId.empty()) firstOverlayId = node->id();
    // On the intraoperative grid: the warped image is "warped" (not a moving image for the rigid
    // registration), the warped statistics and angiograms overlays.
    node->setRole(name == "warped preop image" ? "warped" : "overlay");
    if (name == UncertaintyMapName) {
      node->setDisplay(VolumeDisplay::errorEstimateMm());
    } else if (name != "warped preop image") {
      node->setDisplay(VolumeDisplay::statisticalMap());
    }
  }
  auto labels = scene.add(stored(LabelMapVolumeNode::create("warped preop labels", warpedLabels), warpedLabelsFile));
  labels->setRole("warped");
  auto preop = scene.add(stored(ScalarVolumeNode::create("preop image", shared(context.preopImage("warp"))), o.preopImage));
  preop->setRole("preop");
  preop->setParentTransformId(whole->id());
  auto surface = scene.add(stored(ModelNode::create("brain surface", brainSurface), context.output("brain_surface.vtp")));
  ModelDisplay display;
  display.scalarVisibility = true;
  display.activeScalarName = "DisplacementMagnitude";
  display.colorTable = "ColdToHotRainbow";
  surface->setDisplay(display);
  surface->setParentTransformId(rigid->id());
  // Slicer opens on the scan with the first warped overlay (else the warped image) and labels over it.
  SliceViewLayers layers;
  layers.backgroundVolumeId = intraop->id();
  layers.foregroundVolumeId = firstOverlayId.empty() ? warpedImageId : firstOverlayId;
  layers.labelVolumeId = labels->id();
  scene.setSliceViewLayers(layers);
  writeScene(scene, context.output("scene.mrml"));
}

/// The rigid result on the intraoperative grid, the other candidate the update is judged against
/// (and what is shown when the update is rejected).
struct RigidAlternative {
  DisplacementFieldImage::Pointer field;
  ScalarImage::Pointer image;
  LabelImage::Pointer labels;
};

/// The classification of this scan when the classify stage wrote it on the intraoperative grid.
LabelImage::Pointer intraopLabelsIfWritten(RunContext& context, const ScalarImage& intraop)
{
  const fs::path file = context.output("intraop_labels.nii.gz");
  std::error_code ec;
  if (!fs::exists(file, ec)) return nullptr;
  LabelImage::Pointer labels = context.products().readLabelVolume(file);
  if (!ImageGeometry::of(labels.GetPointer()).sameGridAs(ImageGeometry::of(&intraop))) {
    throw InputError(file.string() + ": not on the intraoperative image's grid (" + ImageGeometry::of(labels.GetPointer()).describe() +
                     ", expected " + ImageGeometry::of(&intraop).describe() + ")");
  }
  return labels;
}

/// Judges the non-rigid update against the rigid result (Logic/Evaluation/NonrigidUpdateTrust.h)
/// with the figures the surface stage reported.
NonrigidUpdateTrustAssessment assessUpdate(RunContext& context, const ScalarImage& intraop, const DeformationField& deformation,
                                           const ScalarImage& warpedImage, const LabelImage& warpedLabels,
                                           const RigidAlternative& rigid)
{
  const LabelImage::Pointer intraopLabels = intraopLabelsIfWritten(context, intraop);
  NonrigidUpdateTrustInputs in;
  in.intraop = &intraop;
  in.warpedByUpdate = &warpedImage;
  in.warpedByRigid = rigid.image.GetPointer();
  in.intraopLabels = intraopLabels.GetPointer();
  in.labelsWarpedByUpdate = &warpedLabels;
  in.labelsWarpedByRigid = rigid.labels.GetPointer();
  in.updateField = deformation.field.GetPointer();
  in.rigidField = rigid.field.GetPointer();
  in.foldedVoxels = deformation.foldedVoxelsInMesh; // the brain's folds; those of the gap above it do not misplace it
  in.meshVoxels = deformation.meshVoxels;
  if (context.report().hasStage("surface")) {
    const nlohmann::json& surface = context.report().stage("surface");
    if (surface.contains("mean_residual_mm") && surface["mean_residual_mm"].is_number()) {
      in.surfaceMeanResidualMm = surface["mean_residual_mm"].get<double>();
    }
    if (surface.contains("surface_nodes") && surface.contains("free_nodes") && surface["free_nodes"].is_object() &&
        surface["free_nodes"].contains("unmatched")) {
      in.surfaceNodes = surface["surface_nodes"].get<std::size_t>();
      // A partial field of view: the share of the nodes it covers that found no boundary.
      if (surface.contains("field_of_view") && surface["field_of_view"].contains("surface_nodes_inside")) {
        in.surfaceNodes = surface["field_of_view"]["surface_nodes_inside"].get<std::size_t>();
      }
      in.unmatchedSurfaceNodes = surface["free_nodes"]["unmatched"].get<std::size_t>();
    }
  }
  return assessNonrigidUpdate(in);
}

nlohmann::json trustEntry(const NonrigidUpdateTrustAssessment& a, double seconds)
{
  auto region = [](const RegionSimilarity& s) {
    return nlohmann::json{{"voxels", s.voxels}, {"update", s.nonrigid}, {"rigid", s.rigid}, {"gain", s.gain()},
                          {"given", s.preoperativeGivenIntraoperative ? "intraoperative" : "preoperative"}};
  };
  const NonrigidUpdateTrustParameters p;
  return {{"nonrigid", trustName(a.trust)},
          {"rigid_fallback", a.trust == UpdateTrust::Rejected},
          {"reasons", a.reasons},
          {"similarity", "correlation ratio eta^2 of the intraoperative image given the warped preoperative image, or of the "
                         "warped preoperative image given the intraoperative one where the update gains more that way "
                         "(each region's \"given\")"},
          {"near_boundary", region(a.band)},
          {"interior", region(a.interior)},
          {"moved", region(a.moved)},
          {"unmatched_surface_node_share", a.unmatchedShare},
          {"folded_voxel_share", a.foldedShare},
          {"thresholds", {{"reject_gain_below", p.rejectGainBelow}, {"doubt_gain_below", p.doubtGainBelow},
                          {"mixed_loss_down_to", p.mixedLossDownTo}, {"mixed_interior_gain_from", p.mixedInteriorGainFrom},
                          {"reject_unmatched_share", p.rejectUnmatchedShare}, {"doubt_unmatched_share", p.doubtUnmatchedShare},
                          {"doubt_residual_mm", p.doubtResidualMm}, {"reject_folded_share", p.rejectFoldedShare},
                          {"doubt_folded_share", p.doubtFoldedShare},
                          {"band_half_width_mm", p.bandHalfWidthMm}, {"moved_mm", p.movedMm}}},
          {"seconds", seconds}};
}

std::string joined(const std::vector<std::string>& parts)
{
  std::string text;
  for (const std::string& part : parts) text += (text.empty() ? "" : "; ") + part;
  return text;
}

/// The whole mapping x = y + d(y) as a transform file: the rigid transform R after the field of what
/// it leaves, e(y) = R^-1(y + d(y)) - y. Inside the field's grid it is the same mapping (R is
/// affine, so interpolating e then applying R is interpolating d); beyond it (a slab scan covers
/// part of the head) the mapping is the rigid one, not the identity a displacement field alone gives
/// outside its grid. R^-1 is affine (A, t): e(y) = A (y + d(y)) + t - y, made in one parallel pass
/// over the grid straight into the doubles the transform file holds.
SpatialTransform::Pointer wholeMappingTransform(const DisplacementFieldImage& field, const SpatialTransform& rigid)
{
  const SpatialTransform::InverseTransformBasePointer inverse = rigid.GetInverseTransform();
  if (!inverse) throw MethodError("warp: the rigid transform cannot be inverted");
  const AffineParameters back = affineParametersOf(inverse.GetPointer());
  auto residual = DoubleDisplacementFieldImage::New();
  residual->CopyInformation(&field);
  residual->SetRegions(field.GetLargestPossibleRegion());
  residual->Allocate();
  const auto size = field.GetLargestPossibleRegion().GetSize();
  // The point of voxel (x, y, z) is o + D S (x, y, z): a step along x adds the column D S e_x.
  const auto& direction = field.GetDirection();
  const auto& spacing = field.GetSpacing();
  const auto& origin = field.GetOrigin();
  double step[3][3];
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) step[c][r] = direction[r][c] * spacing[c];
  }
  const DisplacementVector* d = field.GetBufferPointer();
  DoubleDisplacementFieldImage::PixelType* e = residual->GetBufferPointer();
  parallelRanges(size[2], [&](std::size_t zBegin, std::size_t zEnd, unsigned) {
    for (std::size_t z = zBegin; z < zEnd; ++z) {
      for (std::size_t y = 0; y < size[1]; ++y) {
        std::size_t at = size[0] * (y + size[1] * z);
        double p[3];
        for (int r = 0; r < 3; ++r) p[r] = origin[r] + step[1][r] * double(y) + step[2][r] * double(z);
        for (std::size_t x = 0; x < size[0]; ++x, ++at) {
          const double moved[3] = {p[0] + d[at][0], p[1] + d[at][1], p[2] + d[at][2]};
          for (int r = 0; r < 3; ++r) {
            const double q = back.matrix[r][0] * moved[0] + back.matrix[r][1] * moved[1] + back.matrix[r][2] * moved[2] + back.translation[r];
            e[at][r] = q - p[r];
          }
          for (int r = 0; r < 3; ++r) p[r] += step[0][r];
        }
      }
    }
  });
  auto composite = itk::CompositeTransform<double, 3>::New();
  composite->AddTransform(const_cast<SpatialTransform*>(&rigid)); // applied second
  composite->AddTransform(makeDisplacementFieldTransform(residual.GetPointer())); // applied first
  return SpatialTransform::Pointer(composite.GetPointer());
}

/// The files of the mapping shown, as a field, a transform file and warped volumes; the scene's
/// names for the volumes and their file names.
struct WarpFiles {
  std::vector<std::tuple<std::string, std::string, ScalarImage::Pointer>> scalars; ///< name, file name, volume
  std::string labelsFileName = "warped_preop_labels.nii.gz";
  SpatialTransform::Pointer composite; ///< the whole mapping, as intraop_to_preop.h5 holds it
  std::vector<std::string> fileNames() const
  {
    std::vector<std::string> names{"displacement_intraop_to_preop.nrrd", "intraop_to_preop.h5", labelsFileName};
    for (const auto& scalar : scalars) names.push_back(std::get<1>(scalar));
    return names;
  }
};

/// Writes the mapping's files into `folder`. Touches no run context: it may run beside the trust
/// assessment. The compressed volumes are written on a second thread while this one writes the
/// field and the transform (HDF5, which is not thread-safe, stays on this thread alone).
WarpFiles writeWarpFiles(const fs::path& folder, const std::vector<LoadedOverlay>& overlays, const DisplacementFieldImage::Pointer& field,
                         const ScalarImage::Pointer& warpedImage, const LabelImage::Pointer& warpedLabels,
                         const SpatialTransform::Pointer& rigid, const ScalarImage::Pointer& uncertainty)
{
  WarpFiles files;
  files.scalars.emplace_back("warped preop image", "warped_preop_image.nii.gz", warpedImage);
  if (uncertainty) files.scalars.emplace_back(UncertaintyMapName, "displacement_uncertainty_mm.nii.gz", uncertainty);
  for (const LoadedOverlay& overlay : overlays) {
    files.scalars.emplace_back("warped " + overlay.name, "warped_" + overlay.name + ".nii.gz", warpScalarVolume(*overlay.image, *field));
  }
  std::future<void> volumesWritten = std::async(std::launch::async, [&files, &warpedLabels, &folder] {
    for (const auto& [name, file, image] : files.scalars) writeScalarVolume(image, folder / file);
    writeLabelVolume(warpedLabels, folder / files.labelsFileName);
  });
  try {
    writeDisplacementField(field, folder / "displacement_intraop_to_preop.nrrd");
    files.composite = wholeMappingTransform(*field, *rigid);
    writeTransform(files.composite, folder / "intraop_to_preop.h5");
  } catch (...) {
    volumesWritten.wait(); // the thread's references must outlive it
    throw;
  }
  volumesWritten.get();
  return files;
}

/// A folder beside the outputs where the update's files wait while the trust assessment judges
/// the update (written meanwhile, on other threads): moved into place when it is shown, removed
/// when the rigid result stands in for it, and removed whatever happens when the stage ends.
class StagingFolder {
public:
  explicit StagingFolder(fs::path folder)
    : folder_(std::move(folder))
  {
    std::error_code ec;
    fs::remove_all(folder_, ec); // a run killed before it could clean up
    fs::create_directories(folder_, ec);
    if (ec) throw MethodError("cannot create " + folder_.string() + ": " + ec.message());
  }
  ~StagingFolder()
  {
    std::error_code ec;
    fs::remove_all(folder_, ec);
  }
  StagingFolder(const StagingFolder&) = delete;
  StagingFolder& operator=(const StagingFolder&) = delete;
  const fs::path& path() const { return folder_; }
  /// Each file moved onto its place in `outputDir` (a rename in the same folder tree: atomic).
  void publish(const std::vector<std::string>& fileNames, const fs::path& outputDir) const
  {
    for (const std::string& name : fileNames) {
      std::error_code ec;
      fs::rename(folder_ / name, outputDir / name, ec);
      if (ec) throw MethodError("cannot move " + (folder_ / name).string() + " onto " + (outputDir / name).string() + ": " + ec.message());
    }
  }

private:
  fs::path folder_;
};

/// The scene that points at the mapping's files (in the output folder).
void writeWarpScene(RunContext& context, const WarpFiles& files, const LabelImage::Pointer& warpedLabels,
                    const SpatialTransform::Pointer& rigid, bool rigidFallback)
{
  std::vector<std::tuple<std::string, fs::path, ScalarImage::Pointer>> scalars;
  for (const auto& [name, file, image] : files.scalars) scalars.emplace_back(name, context.output(file), image);
  const fs::path surfaceFile = context.output("brain_surface.vtp");
  vtkSmartPointer<vtkPolyData> brainSurface = vtkPolyData::SafeDownCast(context.products().readModel(surfaceFile));
  if (!brainSurface) throw InputError(surfaceFile.string() + ": not a surface (vtkPolyData)");
  writeUpdateScene(context, scalars, context.output(files.labelsFileName), warpedLabels, rigid, files.composite, brainSurface,
                   rigidFallback);
}

/// A rejected update is kept aside, for whoever must see what was set aside (and for the
/// benchmark that scores the assessment); an accepted one removes an earlier run's.
void keepRejectedUpdate(RunContext& context, const DisplacementFieldImage::Pointer& updateField, const SpatialTransform& rigid,
                        bool rejected)
{
  const fs::path file = context.output("rejected_intraop_to_preop.h5");
  if (!rejected) {
    std::error_code ec;
    fs::remove(file, ec);
    return;
  }
  writeTransform(wholeMappingTransform(*updateField, rigid), file);
}

/// The verdict on the command line; a doubtful update is a warning, a rejected one (its files
/// already the rigid result's) a MethodError with the reasons, once the report is saved.
void reportTrust(RunContext& context, const NonrigidUpdateTrustAssessment& trust)
{
  const bool rejected = trust.trust == UpdateTrust::Rejected;
  context.say("trust: non-rigid update %s (correlation ratio near the brain boundary %.3f, rigid alone %.3f; where it moves "
              "%.3f, rigid alone %.3f)%s\n",
              trustName(trust.trust).c_str(), trust.band.nonrigid, trust.band.rigid, trust.moved.nonrigid, trust.moved.rigid,
              rejected ? ": the files hold the rigid registration alone" : "");
  if (trust.trust == UpdateTrust::Doubtful) {
    context.report().addWarning("warp: the non-rigid update is doubtful: " + joined(trust.reasons));
  } else if (rejected) {
    const std::string message = "warp: the non-rigid update is rejected and the rigid registration is shown instead "
                                "(intraop_to_preop.h5, the displacement field and the warped volumes hold the rigid transform alone; "
                                "the update set aside is rejected_intraop_to_preop.h5): " +
                                joined(trust.reasons);
    context.report().addWarning(message);
    context.report().save();
    throw MethodError(message);
  }
}
/// What the warp reads of the earlier stages' files: the mesh with its displacements and the rigid transform.
struct WarpInputs {
  fs::path meshFile;
  vtkSmartPointer<vtkUnstructuredGrid> mesh;
  SpatialTransform::Pointer rigid;
};

WarpInputs readWarpInputs(RunContext& context)
{
  WarpInputs inputs;
  inputs.meshFile = context.output("mesh.vtu");
  const fs::path rigidFile = context.output("rigid_intraop_to_preop.tfm"), surfaceFile = context.output("brain_surface.vtp");
  for (const auto& [needed, stage] :
       {std::pair<fs::path, const char*>{rigidFile, "rigid"}, {inputs.meshFile, "mesh"}, {surfaceFile, "surface"}}) {
    std::error_code ec;
    if (!fs::exists(needed, ec)) {
      throw InputError(needed.string() + ": not found; run `brainshift " + stage + "` on this output folder first");
    }
  }
  inputs.mesh = vtkUnstructuredGrid::SafeDownCast(context.products().readModel(inputs.meshFile));
  if (!inputs.mesh) throw InputError(inputs.meshFile.string() + ": not a tetrahedral mesh (vtkUnstructuredGrid)");
  inputs.rigid = readTransform(rigidFile);
  if (!isLinearTransform(inputs.rigid)) throw InputError(rigidFile.string() + ": not a rigid transform");
  return inputs;
}

struct WarpSeconds {
  double read = 0, field = 0, warp = 0, trust = 0, write = 0;
};

/// The stage's figures into the report (and the trust verdict's), the folds as a warning, the line on the console.
void reportWarpStage(RunContext& context, const DeformationField& deformation, bool rigidFallback, double wallSeconds,
                     const WarpSeconds& seconds, const nlohmann::json& uncertaintyEntry, const NonrigidUpdateTrustAssessment& trust)
{
  context.report().setStage("warp", {{"wall_seconds", wallSeconds},
                                     {"voxels", deformation.voxels},
                                     {"mesh_voxels", deformation.meshVoxels},
                                     {"folded_voxels", deformation.foldedVoxels},
                                     {"folded_voxels_in_mesh", deformation.foldedVoxelsInMesh},
                                     {"min_jacobian_determinant", deformation.minimumJacobian},
                                     {"inverted_deformed_tetrahedra", deformation.invertedDeformedTetrahedra},
                                     {"max_non_rigid_mm", deformation.maximumNonRigidMm},
                                     {"fallback_sigma_mm", deformation.fallbackSigmaMm},
                                     {"continuation_band_mm", deformation.continuationBandMm},
                                     {"continued_voxels", deformation.continuedVoxels},
                                     {"volumes_warped", 2 + context.overlays().size()},
                                     {"rigid_fallback", rigidFallback},
                                     {"read_seconds", seconds.read},
                                     {"field_seconds", seconds.field},
                                     {"locate_seconds", deformation.locateSeconds},
                                     {"fallback_seconds", deformation.fallbackSeconds},
                                     {"jacobian_seconds", deformation.jacobianSeconds},
                                     {"warp_seconds", seconds.warp},
                                     {"trust_seconds", seconds.trust},
                                     {"write_seconds", seconds.write},
                                     {"uncertainty", uncertaintyEntry}});
  context.report().set("trust", trustEntry(trust, seconds.trust));
  if (deformation.foldedVoxels > 0) {
    context.report().addWarnings({"warp: " + std::to_string(deformation.foldedVoxels) +
                                  " voxels where the deformation folds (Jacobian determinant <= 0), " +
                                  std::to_string(deformation.foldedVoxelsInMesh) + " of them in the brain's mesh"});
  }
  context.say("warp: %zu voxels (%zu in the mesh), %zu folded, field %.2f s, warp %.2f s, trust %.2f s, files %.2f s more\n",
              deformation.voxels, deformation.meshVoxels, deformation.foldedVoxels, seconds.field, seconds.warp, seconds.trust,
              seconds.write);
}
} // namespace

void runWarpStage(RunContext& context)
{
  Stopwatch clock;
  WarpSeconds seconds;
  const WarpInputs inputs = readWarpInputs(context);
  const SpatialTransform::Pointer& rigid = inputs.rigid;
  const ScalarImage& intraop = context.intraopImage("warp");
  const ScalarImage& preopImage = context.preopImage("warp");
  const LabelImage& preopLabels = context.preopLabels("warp");
  const std::vector<LoadedOverlay>& overlays = context.overlays();
  seconds.read = clock.seconds();

  Stopwatch fieldClock;
  const DeformationField deformation =
    intraopToPreopField(inputs.mesh, *rigid, ImageGeometry::of(&intraop), DeformationFieldParameters{}, inputs.meshFile.string());
  RigidAlternative rigidOnly{linearTransformField(*rigid, ImageGeometry::of(&intraop)), nullptr, nullptr};
  seconds.field = fieldClock.seconds();
  Stopwatch warpClock;
  ScalarImage::Pointer warpedImage = warpScalarVolume(preopImage, *deformation.field);
  LabelImage::Pointer warpedLabels = warpLabelVolume(preopLabels, *deformation.field);
  rigidOnly.image = warpScalarVolume(preopImage, *rigidOnly.field);
  rigidOnly.labels = warpLabelVolume(preopLabels, *rigidOnly.field);
  seconds.warp = warpClock.seconds();

  // Never a deformed image worse than the rigid one without a word: a rejected update gives way
  // to the rigid result in every file, and the command fails with the reason once they are written.
  // The update's files are written into a staging folder while the trust assessment judges it (the
  // two share the machine's cores), and moved into place only when it is shown.
  nlohmann::json uncertaintyEntry = nullptr;
  // The confidence map, made before the trust has judged the update (dropped if it is rejected).
  const ScalarImage::Pointer uncertainty = uncertaintyOnScan(inputs.mesh, *deformation.field, inputs.meshFile.string(), uncertaintyEntry);
  Stopwatch writeClock;
  const StagingFolder staging(context.output(".warp-staging"));
  std::future<WarpFiles> updateFiles = std::async(std::launch::async, [&] {
    return writeWarpFiles(staging.path(), overlays, deformation.field, warpedImage, warpedLabels, rigid, uncertainty);
  });
  Stopwatch trustClock;
  const NonrigidUpdateTrustAssessment trust = assessUpdate(context, intraop, deformation, *warpedImage, *warpedLabels, rigidOnly);
  seconds.trust = trustClock.seconds();
  const bool rigidFallback = trust.trust == UpdateTrust::Rejected;
  WarpFiles shown;
  if (!rigidFallback) {
    shown = updateFiles.get();
    staging.publish(shown.fileNames(), context.options().outputDir);
  } else {
    updateFiles.wait(); // set aside, whatever became of it
    uncertaintyEntry = nullptr;
    std::error_code ec;
    fs::remove(context.output("displacement_uncertainty_mm.nii.gz"), ec);
    shown = writeWarpFiles(context.options().outputDir, overlays, rigidOnly.field, rigidOnly.image, rigidOnly.labels, rigid,
                           nullptr);
  }
  writeWarpScene(context, shown, rigidFallback ? rigidOnly.labels : warpedLabels, rigid, rigidFallback);
  keepRejectedUpdate(context, deformation.field, *rigid, rigidFallback);
  seconds.write = std::max(0.0, writeClock.seconds() - seconds.trust); // beyond the assessment, which it overlaps
  reportWarpStage(context, deformation, rigidFallback, clock.seconds(), seconds, uncertaintyEntry, trust);
  reportTrust(context, trust);
}

} // namespace brainshift
