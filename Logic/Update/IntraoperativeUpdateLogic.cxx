#include "IntraoperativeUpdateLogic.h"

#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "OutputFolder.h"
#include "RunReport.h"
#include "VolumeIO.h"

#include <chrono>
#include <cstdio>

namespace brainshift {
namespace fs = std::filesystem;

ScanFolderWatcher::ScanFolderWatcher(fs::path folder)
  : folder_(std::move(folder))
{
  std::error_code ec;
  if (!fs::is_directory(folder_, ec)) throw InputError(folder_.string() + ": the watched folder is not a folder");
}

std::optional<fs::path> ScanFolderWatcher::next()
{
  std::error_code ec;
  std::set<fs::path> candidates;
  for (const auto& entry : fs::directory_iterator(folder_, ec)) {
    if (entry.is_regular_file(ec) && isVolumePath(entry.path()) && !taken_.count(entry.path())) candidates.insert(entry.path());
  }
  for (const fs::path& file : candidates) { // name order
    const auto size = fs::file_size(file, ec);
    if (ec) continue;
    auto [at, fresh] = lastSize_.emplace(file, size);
    if (fresh || at->second != size) {
      at->second = size;
      continue; // seen for the first time or still growing: next poll
    }
    taken_.insert(file);
    return file;
  }
  return std::nullopt;
}

IntraoperativeUpdateLogic::IntraoperativeUpdateLogic(RunOptions caseOptions)
  : caseOptions_(std::move(caseOptions))
  , configuration_(configurationFor(caseOptions_))
{
  caseOptions_.intraopImage.clear();
  caseOptions_.previous.clear();
  if (caseOptions_.outputDir.empty()) throw InputError("the session needs an output folder");
}

IntraoperativeUpdateLogic::~IntraoperativeUpdateLogic() = default;

void IntraoperativeUpdateLogic::claimSessionFolder()
{
  if (folderClaimed_) return;
  const fs::path& folder = caseOptions_.outputDir;
  claimOutputFolder(folder); // before the earlier session's check: one session per folder
  std::error_code ec;
  if (fs::exists(summaryFile(), ec)) { // an earlier session's scans: kept unless told otherwise
    if (!caseOptions_.overwrite) {
      throw InputError(folder.string() + ": holds an earlier watch session (watch.json); choose another output folder, "
                       "or pass --overwrite to replace its scans");
    }
    for (const auto& entry : fs::directory_iterator(folder, ec)) {
      const std::string name = entry.path().filename().string();
      if (entry.is_directory(ec) && (name.rfind("scan-", 0) == 0 || name == "received" || name == "preoperative")) fs::remove_all(entry.path(), ec);
    }
    fs::remove(summaryFile(), ec);
  }
  folderClaimed_ = true;
}

void IntraoperativeUpdateLogic::prepare(const UpdateProgressCallback& progress)
{
  if (prepared_) return;
  claimSessionFolder();
  RunOptions preparation = caseOptions_;
  preparation.outputDir = preparedFolder();
  std::error_code ec;
  fs::create_directories(preparation.outputDir, ec);
  if (ec) throw InputError(preparation.outputDir.string() + ": cannot create the folder (" + ec.message() + ")");
  RunReport report(preparation.outputDir / "report.json");
  report.clear();
  RunContext context(preparation, configuration_, report);
  context.joinSession(session_);
  if (progress) context.setProgressCallback(progress);
  session_.cancelRequested = false;
  context.setCancelFlag(&session_.cancelRequested);
  context.loadPreoperativeInputs();
  report.set("case_inputs", preoperativeFingerprint(context));
  try {
    runPreparation(context); // the mesh, the preoperative boundary, the served worker
  } catch (const std::exception&) {
    session_.worker.reset();
    report.save();
    throw;
  }
  report.save();
  prepared_ = true;
}

void IntraoperativeUpdateLogic::cancel()
{
  session_.cancelRequested = true;
}

namespace {
/// What a scan's report says of its stages, warnings and trust.
void readScanReport(const RunReport& report, ScanUpdate& scan)
{
  const nlohmann::json& document = report.document();
  if (document.contains("stages")) {
    for (const PipelineStage& stage : pipelineStages()) {
      if (document["stages"].contains(stage.name)) {
        scan.stageSeconds.emplace_back(stage.name, document["stages"][stage.name].value("wall_seconds", 0.0));
      }
    }
  }
  if (document.contains("warnings")) {
    for (const auto& warning : document["warnings"]) {
      if (warning.is_string()) scan.warnings.push_back(warning.get<std::string>());
    }
  }
  scan.trust = nonrigidUpdateTrustIn(document);
}
} // namespace

void IntraoperativeUpdateLogic::registerScan(ScanUpdate& scan, const UpdateProgressCallback& progress)
{
  RunOptions run = caseOptions_;
  run.intraopImage = scan.intraopImage;
  run.outputDir = scan.outputDir;
  run.previous = previous_.value_or(preparedFolder()); // the first scan starts from what was prepared before surgery
  run.previousIsPreparation = !previous_;
  run.overwrite = true; // the session's own folders (an earlier session's were removed by prepare)
  const auto start = std::chrono::steady_clock::now();
  RunReport report(run.outputDir / "report.json");
  report.clear(); // a scan folder of an earlier session is replaced
  try {
    RunContext context(run, configuration_, report);
    context.joinSession(session_);
    context.setCancelFlag(&session_.cancelRequested);
    if (progress) context.setProgressCallback(progress);
    runRegistration(context);
    scan.wallSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    report.set("scan_wall_seconds", scan.wallSeconds);
    report.save();
    scan.registered = true;
    scan.outcome = "registered";
  } catch (const CancelledError& e) {
    scan.cancelled = true;
    scan.outcome = scan.failure = "cancelled";
    report.addWarning(std::string("the update was cancelled: ") + e.what());
    report.save();
  } catch (const std::exception& e) { // one scan's failure does not end the session
    scan.failure = e.what();
    scan.outcome = "failed: " + scan.failure;
  }
  if (!scan.registered) {
    scan.wallSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    // A worker cancelled or failed mid-solve is not trusted with the next scan (a scan that failed
    // before the solve, or after it, leaves the served worker as it was).
    const bool inSolve = report.hasStage("surface") && !report.hasStage("simulate");
    if (scan.cancelled || inSolve) session_.worker.reset();
  }
  readScanReport(report, scan); // a rejected update has left the rigid result in every file: the trust says so
}

ScanUpdate IntraoperativeUpdateLogic::update(const fs::path& intraopImage, const std::string& source,
                                             const UpdateProgressCallback& progress)
{
  prepare();
  ScanUpdate scan;
  scan.number = unsigned(scans_.size() + 1);
  scan.intraopImage = intraopImage;
  scan.source = source;
  char folderName[32];
  std::snprintf(folderName, sizeof folderName, "scan-%02u", scan.number);
  scan.outputDir = caseOptions_.outputDir / folderName;
  std::error_code ec;
  fs::create_directories(scan.outputDir, ec);
  session_.cancelRequested = false;
  if (ec) {
    scan.failure = scan.outputDir.string() + ": cannot create the scan's folder (" + ec.message() + ")";
    scan.outcome = "failed: " + scan.failure;
  } else {
    registerScan(scan, progress);
  }
  if (scan.registered) {
    previous_ = scan.outputDir;
    ++session_.scans;
  }
  scan.entry = {{"scan", scan.number},
                {"intraop_image", fs::absolute(intraopImage).string()},
                {"output_dir", scan.outputDir.string()},
                {"source", source},
                {"wall_seconds", scan.wallSeconds},
                {"outcome", scan.outcome},
                {"trust", scan.trust}};
  if (scan.registered) {
    nlohmann::json stages = nlohmann::json::object();
    for (const auto& [stage, seconds] : scan.stageSeconds) stages[stage] = seconds;
    scan.entry["stage_seconds"] = stages;
  }
  scans_.push_back(scan);
  saveSummary();
  return scan;
}

nlohmann::json IntraoperativeUpdateLogic::summary(const nlohmann::json& extra) const
{
  nlohmann::json document = {{"preop_image", fs::absolute(caseOptions_.preopImage).string()},
                             {"preop_labels", fs::absolute(caseOptions_.preopLabels).string()},
                             {"scans", nlohmann::json::array()}};
  for (const ScanUpdate& scan : scans_) document["scans"].push_back(scan.entry);
  for (const auto& [key, value] : extra.items()) document[key] = value;
  return document;
}

void IntraoperativeUpdateLogic::saveSummary(const nlohmann::json& extra) const
{
  writeTextFileAtomically(summaryFile(), summary(extra).dump(2) + "\n");
}

} // namespace brainshift
