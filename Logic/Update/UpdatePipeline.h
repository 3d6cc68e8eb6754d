#pragma once
// The intraoperative update as the logic runs it: a case's inputs and overrides (RunOptions), the
// configuration with those overrides over it, the inputs read once, the serial-scan session (what a
// case keeps between its scans), and the pipeline of stages in order, each stage reading its inputs
// from and writing its results into the case's output folder. The command line (register, watch,
// demo, the stage subcommands) and the host's "Intraoperative update" module are its front ends
// (IntraoperativeUpdateLogic.h drives a session of scans).
#include "BrainShiftErrors.h"
#include "Configuration.h"
#include "DisplacementUncertainty.h"
#include "DistanceMaps.h"
#include "FiniteElementSolver.h"
#include "RigidRegistrationLogic.h"
#include "TissueClassificationLogic.h"
#include "RegistrationInputs.h"
#include "RunReport.h"
#include "StageProducts.h"

#include <atomic>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

class vtkUnstructuredGrid;

namespace brainshift {

/// A case's inputs and the overrides of its configuration (the command line's flags, the module's
/// fields): `register`, its stages and a session's scans share them.
struct RunOptions {
  std::filesystem::path preopImage, preopLabels, intraopImage, outputDir, config;
  std::vector<std::string> overlays; ///< NAME=FILE
  std::optional<int> ranks;
  std::optional<double> meshResolutionMm;
  std::optional<std::string> meshBackend;
  std::optional<double> meshGrading;
  std::vector<double> meshRegionOfInterest; ///< x, y, z (LPS mm), radius mm; empty: the configuration's
  std::optional<std::string> solverOptions;
  std::filesystem::path prototypes; ///< classification prototypes (recorded or picked); empty: automatic
  std::optional<std::string> tumourResected; ///< "yes", "no" or "auto" (the configuration's otherwise)
  /// An earlier scan's output folder of the same case (register --previous): its rigid transform
  /// starts the registration, its prototypes classify, its mesh and preoperative surface fit are reused.
  std::filesystem::path previous;
  /// `previous` is the folder a session prepared before surgery (runPreparation), not a scan.
  bool previousIsPreparation = false;
  bool overwrite = false; ///< register into a folder holding another case's results
};

/// Where an update is: the stage starting (`fraction` 0) or a step within it (a line of `message`).
struct UpdateProgress {
  std::string stage;   ///< the stage's name ("rigid", "classify", ...)
  std::size_t index;   ///< the stage's place in the pipeline, from 0
  std::size_t count;   ///< the stages of the pipeline
  std::string message; ///< what the stage did or is doing; empty when it starts
};
using UpdateProgressCallback = std::function<void(const UpdateProgress&)>;

/// The configuration file (or the defaults) with the overrides over it, validated.
Configuration configurationFor(const RunOptions& options);

/// What `brainshift watch` keeps between the scans of one case, in memory: the preoperative inputs
/// (read and checked once, before surgery) and the finite element worker, served (its partition
/// and assembled matrix kept; each scan's fixed nodes eliminated anew). A run outside a session
/// keeps one of its own between the passes of its stages (RunContext::kept).
struct SerialScanSession {
  std::optional<RegistrationInputs> preoperative; ///< preoperative image, labels, overlays
  std::shared_ptr<const PreoperativeTissueMaps> tissueMaps; ///< the classification's, of those labels
  std::shared_ptr<const PreparedRigidMoving> rigidMoving;   ///< the rigid registration's, of that image
  /// The preoperative inputs' fingerprints (report.json "case_inputs"), hashed once a session: the
  /// data are the session's, the same for every scan (0.04 s of each scan's start otherwise).
  nlohmann::json preoperativeFingerprint;
  /// The served worker outlives one scan's context: its progress goes through here (set by the
  /// simulate stage for its scan), and its cancellation is this flag (the session's Cancel).
  /// Declared before the worker, so that they outlive it (its shutdown may still report).
  std::function<void(const std::string&)> solveProgress;
  std::atomic<bool> cancelRequested{false};
  std::unique_ptr<FiniteElementSession> worker;
  int scans = 0; ///< scans registered so far
};

/// Where the first solve put the tumour, when the first classification decided on it by the image
/// (the refine stage's second look): its voxels voting as the tumour's prototypes did.
struct TumourSecondLook {
  nlohmann::json entry = nullptr; ///< null: not looked at (no tumour, or decided by the user or an earlier scan)
  /// The decision where the solve put the tumour (resected or not), when it overturns the first
  /// classification's; empty when that one stands.
  std::optional<bool> overturnedTo;
  std::string warning; ///< the vote says resected without air: kept in place, said when the look is taken
};

struct BlockMatchingResult;
class PreparationAhead;

/// The block matches of this scan's last matching, and the tumour decision they were made under
/// (a resected tumour's blocks are not matched).
struct KeptBlockMatches {
  std::shared_ptr<const BlockMatchingResult> matching;
  bool tumourResected = false;
};

/// One run of stages on one case: its options, configuration and report, and its inputs, each read
/// and checked once, when a stage first asks for it.
class RunContext {
public:
  RunContext(RunOptions options, Configuration configuration, RunReport& report);

  /// Observes the pipeline: each stage as it starts and each line a stage reports. Without one, the
  /// lines go to standard output (the command line's log).
  void setProgressCallback(UpdateProgressCallback callback) { progress_ = std::move(callback); }
  /// Polled between the stages and handed to each stage's logic: CancelledError when set.
  void setCancelFlag(CancelFlag cancel) { cancel_ = cancel; }
  CancelFlag cancelFlag() const { return cancel_; }
  /// A stage's line of progress (printf-style): to the callback, or to standard output.
  void say(const char* format, ...) __attribute__((format(printf, 2, 3)));
  /// The pipeline's: `stage` (index of count) starts.
  void stageStarts(const std::string& stage, std::size_t index, std::size_t count);

  const RunOptions& options() const { return options_; }
  const Configuration& configuration() const { return configuration_; }
  RunReport& report() { return report_; }
  std::filesystem::path output(const std::string& fileName) const { return options_.outputDir / fileName; }
  /// What the stages of this run wrote, kept for the later ones (StageProducts: the data bus).
  StageProducts& products() { return products_; }

  /// Reads and checks every input given at once (`register` does this first).
  void loadAllInputs();
  /// Reads and checks the preoperative inputs alone (image, labels, overlays) into the session, before
  /// any scan (a session prepared before surgery); a no-op when the session holds them already.
  void loadPreoperativeInputs();
  /// InputError naming the missing flag when the stage needs an input it was not given.
  const ScalarImage& preopImage(const std::string& stage);
  const ScalarImage& intraopImage(const std::string& stage);
  /// The labels when given, else null.
  const LabelImage* preopLabelsIfGiven();
  const LabelImage& preopLabels(const std::string& stage);
  /// The --overlay volumes, read and checked once.
  const std::vector<LoadedOverlay>& overlays();
  /// A file of the previous scan's output folder (--previous), when one was given and holds it.
  std::optional<std::filesystem::path> previousFile(const std::string& fileName) const;
  /// The previous scan's report (empty when none was given).
  const nlohmann::json& previousReport() const { return previousReport_; }
  /// Takes --previous for this case (`fingerprint`: caseFingerprint's): InputError naming the
  /// folder when it is missing, holds no report, or is another case's.
  void usePreviousScan(const nlohmann::json& fingerprint);
  /// Runs within a watch session: the preoperative inputs come from (or go into) it, and the
  /// simulate stage solves with its served worker.
  void joinSession(SerialScanSession& session) { session_ = &session; }
  SerialScanSession* session() const { return session_; }
  /// What the stages keep between their passes: the watch session (kept between scans too), or
  /// this run's own (its worker, started by the first solve with block matching and kept for the
  /// later ones: the block matches' solve, the refine stage's passes, the tumour's second look
  /// solve the same mesh, partitioned and assembled once; the preoperative tissue maps, classified
  /// against again). The run's own stops its worker when the run ends.
  SerialScanSession& kept() { return session_ ? *session_ : keptByRun_; }
  /// The refine stage's spatial prior: the preoperative labels warped onto the intraoperative grid
  /// by the last solve (classify then uses them with the identity instead of the preoperative labels
  /// through the rigid transform, and surface reuses the preoperative boundary it found); null: none.
  /// `moved` (on the same grid) marks where the solve moved the tissue: only there does the new
  /// classification replace `anchor`, the classification through the rigid prior (or the tumour
  /// decision pass's, which kept it elsewhere: the two priors agree there, and an ambiguous
  /// boundary left to the prior alone would follow the last pass's own error from pass to pass).
  void setWarpedPrior(LabelImage::Pointer labels, int pass, MaskImage::Pointer moved = nullptr, LabelImage::Pointer anchor = nullptr)
  {
    warpedPrior_ = std::move(labels);
    warpedPriorPass_ = pass;
    movedByPrior_ = std::move(moved);
    anchorLabels_ = std::move(anchor);
  }
  /// A decision on the tumour that the classification takes instead of its own (unless the user
  /// gave one), and who made it: the refine stage's (where the first solve put the tumour; or the
  /// first classification's, which a refine pass keeps: the warped prior carries the first solve's
  /// errors into the place where the tumour is looked at). Cleared with std::nullopt.
  struct HeldTumourDecision {
    bool resected = false;
    std::string decidedBy;
  };
  void holdTumourDecision(std::optional<HeldTumourDecision> decision) { heldTumourDecision_ = std::move(decision); }
  const std::optional<HeldTumourDecision>& heldTumourDecision() const { return heldTumourDecision_; }
  /// The tumour's second look, when the simulate stage made it on its first solve (before the
  /// block matches): the refine stage takes it instead of looking again.
  void keepTumourSecondLook(TumourSecondLook look) { tumourSecondLook_ = std::move(look); }
  std::optional<TumourSecondLook> takeTumourSecondLook() { return std::exchange(tumourSecondLook_, std::nullopt); }
  /// The whole pipeline runs (runPipeline: `register`, `watch`, `demo`), so the refine stage follows
  /// the simulate stage in this run; a stage run alone is not.
  void setWholePipeline(bool whole) { wholePipeline_ = whole; }
  bool wholePipeline() const { return wholePipeline_; }
  /// Another pass over this scan (the refine stage's): the surface stage starts from the
  /// preoperative boundary this scan's own surface holds.
  void setRepeatPass(bool repeat) { repeatPass_ = repeat; }
  bool repeatPass() const { return repeatPass_ || warpedPrior_; }
  /// The mesh and the preoperative boundary this run makes beside its first stages
  /// (PreparationAhead, started by runPipeline); null: the mesh and surface stages make their own.
  void setPreparationAhead(std::shared_ptr<PreparationAhead> ahead) { preparationAhead_ = std::move(ahead); }
  PreparationAhead* preparationAhead() const { return preparationAhead_.get(); }
  /// The block matches of this scan's last fresh matching: a refine pass's solve holds them
  /// against its classification instead of matching again (under the same tumour decision).
  void keepBlockMatches(KeptBlockMatches matches) { blockMatches_ = std::move(matches); }
  const std::optional<KeptBlockMatches>& keptBlockMatches() const { return blockMatches_; }
  /// The evidence behind the last solve of this run (its imposed nodes and matches, with their
  /// misfits): the confidence map's, which the refine stage adds its passes' disagreement to.
  void setSolveEvidence(DisplacementEvidence evidence) { solveEvidence_ = std::move(evidence); }
  const std::optional<DisplacementEvidence>& solveEvidence() const { return solveEvidence_; }
  const LabelImage* warpedPrior() const { return warpedPrior_.GetPointer(); }
  int warpedPriorPass() const { return warpedPriorPass_; }
  const MaskImage* movedByPrior() const { return movedByPrior_.GetPointer(); }
  const LabelImage* anchorLabels() const { return anchorLabels_.GetPointer(); }

private:
  RunOptions options_;
  Configuration configuration_;
  RunReport& report_;
  std::optional<RegistrationInputs> inputs_;
  ScalarImage::Pointer preopImage_, intraopImage_;
  LabelImage::Pointer preopLabels_;
  std::optional<std::vector<LoadedOverlay>> overlays_;
  nlohmann::json previousReport_;
  SerialScanSession* session_ = nullptr;
  UpdateProgressCallback progress_;
  CancelFlag cancel_ = nullptr;
  UpdateProgress current_{"", 0, 0, ""};
  LabelImage::Pointer warpedPrior_;
  int warpedPriorPass_ = 0;
  MaskImage::Pointer movedByPrior_;
  LabelImage::Pointer anchorLabels_;
  std::optional<HeldTumourDecision> heldTumourDecision_;
  bool repeatPass_ = false;
  bool wholePipeline_ = false;
  std::optional<TumourSecondLook> tumourSecondLook_;
  std::optional<KeptBlockMatches> blockMatches_;
  std::shared_ptr<PreparationAhead> preparationAhead_;
  StageProducts products_;
  std::optional<DisplacementEvidence> solveEvidence_;
  /// Last: its worker stops first, while what its progress and cancellation reach still lives.
  SerialScanSession keptByRun_;
};

/// The case's identity, kept in report.json as "case_inputs": the paths of the preoperative image
/// and labels and of the intraoperative image, and fingerprints of what they hold (64-bit FNV-1a of
/// the voxels and the geometry; the same data in another file or format is the same). A later scan
/// of the same case has the same preoperative data.
nlohmann::json caseFingerprint(RunContext& context);

/// A stage alone: refuses an output folder whose report records another case's preoperative
/// image or labels than those given (InputError, before the stage works) unless --overwrite (then
/// the report starts afresh), and records the given inputs' fingerprints in "case_inputs".
void claimCaseForStage(RunContext& context, const std::string& stage);

/// `register`: reads and checks the inputs, refuses an output folder whose report records another
/// case's inputs (InputError, before anything is written) unless --overwrite (then the report
/// starts afresh), takes the previous scan (--previous), records the case's fingerprint, and runs
/// every stage. The report is saved after each stage and on failure.
void runRegistration(RunContext& context);

/// How a run of every stage ended for a front end that evaluates whatever the run wrote (the demo).
struct RegistrationEnd {
  bool pipelineComplete = false; ///< every stage ran, and the update was not rejected
  /// A stage's tool is missing (NotAvailableError): the stages before it wrote their files.
  std::optional<NotAvailableError> notAvailable;
  /// The trust assessment rejected the non-rigid update: the rigid result is in every file and the
  /// update set aside is rejected_intraop_to_preop.h5 (the error register would have ended with).
  std::optional<MethodError> rejected;
};

/// runRegistration, with a missing tool and a rejected non-rigid update returned instead of thrown
/// (the report, saved, records them as warnings); any other failure is thrown, as runRegistration does.
RegistrationEnd runRegistrationForEvaluation(RunContext& context);

/// The trust assessment's verdict in a run's report.json document ("trusted", "doubtful",
/// "rejected": the rigid result stands in every file), or "not assessed" when the run did not get that far.
std::string nonrigidUpdateTrustIn(const nlohmann::json& report);

/// A stage of the intraoperative update.
struct PipelineStage {
  std::string name;    ///< the subcommand
  std::string summary; ///< one line for --help
  /// Runs the stage on the case; empty while the stage is not built. A result that cannot be
  /// trusted is a MethodError (exit 1).
  std::function<void(RunContext&)> run;
};

/// The stages in the order `register` runs them.
const std::vector<PipelineStage>& pipelineStages();

/// Runs the stages in order, saving the report after each. Stops at the first stage that is not
/// built with NotAvailableError; a failing stage stops the pipeline with its reason.
void runPipeline(RunContext& context);

/// The stages (StageRunners.cxx).
void runRigidStage(RunContext& context);
void runClassifyStage(RunContext& context);
void runSimulateStage(RunContext& context);
void runMeshStage(RunContext& context);
void runSurfaceStage(RunContext& context);
void runWarpStage(RunContext& context);
void runRefineStage(RunContext& context); ///< RefineStage.cxx
/// The refine stage's second look at the tumour, made early on the first solve of a scan
/// (`firstSolve`, its displacements attached; `meshName` names it in errors): whether where that
/// solve puts the tumour overturns the first classification's decision (resected where it was
/// found in place, or in place where it was found resected). Then the look is kept for the refine
/// stage, which classifies and solves again under the new decision; else the refine stage looks
/// again on the scan's final solve (and this look leaves nothing behind). False in the refine
/// stage's own passes, and where no refine stage follows in this run (a stage run alone).
bool secondLookOverturnsTumourDecision(RunContext& context, vtkUnstructuredGrid* firstSolve, const std::string& meshName);
/// The tumour's evidence as report.json keeps it (null without a tumour).
nlohmann::json tumourEvidenceJson(const TumourResectionEvidence& evidence);

/// Before surgery, into the context's output folder, from the preoperative data alone: the mesh
/// (mesh.vtu), the preoperative brain surface with each node's preoperative boundary
/// (brain_surface.vtp: what a scan's surface stage reuses) and, in a session, the served finite
/// element worker partitioned and assembled on them. A first scan given this folder as its
/// `previous` (with previousIsPreparation) reuses the mesh, the boundary and the worker. The
/// context's report needs "case_inputs" (preoperativeFingerprint) for that.
void runPreparation(RunContext& context);

/// caseFingerprint's preoperative part (the image and the labels).
nlohmann::json preoperativeFingerprint(RunContext& context);

} // namespace brainshift
