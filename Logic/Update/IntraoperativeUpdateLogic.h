#pragma once
// The intraoperative update of one case, scan after scan (after Slicer's module logic and
// elastix's library call): prepared before surgery with the preoperative data (read and checked
// once, kept in memory), then updated with each intraoperative scan. Each scan runs the whole
// pipeline (UpdatePipeline.h) into OUT/scan-NN/ exactly as `register --previous` would (every file,
// report.json, scene.mrml), starting from the scan before it and sharing the preoperative data and
// the served finite element worker. OUT/watch.json lists the scans, their times and outcomes and
// the trust in each one's non-rigid update, rewritten after each. `brainshift watch` and the host's
// "Intraoperative update" module are its front ends. No Qt; update() runs on the caller's thread and
// may be cancelled from any other.
#include "UpdatePipeline.h"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace brainshift {

/// The images a scanner writes into a folder, each taken once, in name order, once its size has
/// stayed the same over one poll (the scanner may still be writing it).
class ScanFolderWatcher {
public:
  /// InputError naming the folder when it is not one.
  explicit ScanFolderWatcher(std::filesystem::path folder);
  /// The next image not yet taken that is complete; none while none is.
  std::optional<std::filesystem::path> next();
  const std::filesystem::path& folder() const { return folder_; }

private:
  std::filesystem::path folder_;
  std::set<std::filesystem::path> taken_;
  std::map<std::filesystem::path, std::uintmax_t> lastSize_;
};

/// One scan of the session and what became of it.
struct ScanUpdate {
  unsigned number = 0;                 ///< 1, 2, ... in the order the scans came
  std::filesystem::path intraopImage;  ///< the scan
  std::filesystem::path outputDir;     ///< OUT/scan-NN/
  std::string source;                  ///< where it came from ("--scans", "--watch-dir", "the host", ...)
  bool registered = false;             ///< the pipeline ran to its end (the update may still be rejected: trust)
  bool cancelled = false;              ///< stopped by cancel(); nothing of it is used by later scans
  std::string outcome;                 ///< "registered", "cancelled" or "failed: <reason>"
  std::string failure;                 ///< why it was not registered: the reason, or "cancelled"; empty when registered
  /// The trust assessment's verdict on the non-rigid update: "trusted", "doubtful", "rejected" (the
  /// rigid result stands in every file), or "not assessed" when the update did not get that far.
  std::string trust = "not assessed";
  double wallSeconds = 0;                          ///< from the image to the warped volumes
  std::vector<std::pair<std::string, double>> stageSeconds; ///< in pipeline order
  std::vector<std::string> warnings;               ///< the scan's report's
  nlohmann::json entry;                            ///< its watch.json entry (front ends may add to it)
};

class IntraoperativeUpdateLogic {
public:
  /// The case: preoperative image, labels, overlays, the session's output folder and the
  /// configuration's overrides (`caseOptions.intraopImage` and `previous` are ignored). The
  /// configuration is validated here (InputError).
  explicit IntraoperativeUpdateLogic(RunOptions caseOptions);
  ~IntraoperativeUpdateLogic();
  IntraoperativeUpdateLogic(const IntraoperativeUpdateLogic&) = delete;
  IntraoperativeUpdateLogic& operator=(const IntraoperativeUpdateLogic&) = delete;

  /// Before surgery: claims the output folder (an earlier session there is refused with InputError
  /// unless `overwrite`, then its scans are removed), reads and checks the preoperative data once,
  /// and prepares in OUT/preoperative/ what every scan reuses (runPreparation: the mesh, the
  /// preoperative brain boundary, the served finite element worker), reporting its steps to
  /// `progress`. InputError for bad preoperative data, MethodError when the mesh or the worker
  /// fails. update() prepares when it was not done.
  void prepare(const UpdateProgressCallback& progress = {});
  /// prepare()'s first step alone, for a front end that must own the folder before the data are
  /// read (watch starts its OpenIGTLink server there): claimed once, later calls do nothing.
  void claimSessionFolder();
  bool prepared() const { return prepared_; }

  /// Registers one scan into OUT/scan-NN/, reporting each stage and each stage's lines to
  /// `progress` (on this thread). Never throws for a scan's own failure or cancellation: the
  /// outcome says it (and the scan is not used by later ones); InputError only for a session that
  /// cannot be prepared. watch.json is rewritten before it returns.
  ScanUpdate update(const std::filesystem::path& intraopImage, const std::string& source,
                    const UpdateProgressCallback& progress = {});
  /// From any thread: the running update stops at its next check (the finite element worker is
  /// terminated) and its outcome is "cancelled". No effect when none runs.
  void cancel();

  /// The scans so far, in order (the front end's history); the last may be amended (entry) before
  /// saveSummary().
  const std::vector<ScanUpdate>& scans() const { return scans_; }
  ScanUpdate& lastScan() { return scans_.back(); }
  /// The session's summary (watch.json): the case, each scan's entry, and `extra`'s keys.
  nlohmann::json summary(const nlohmann::json& extra = nlohmann::json::object()) const;
  /// Rewrites watch.json atomically.
  void saveSummary(const nlohmann::json& extra = nlohmann::json::object()) const;
  std::filesystem::path summaryFile() const { return caseOptions_.outputDir / "watch.json"; }
  /// What prepare() made before surgery (OUT/preoperative/).
  std::filesystem::path preparedFolder() const { return caseOptions_.outputDir / "preoperative"; }
  const RunOptions& caseOptions() const { return caseOptions_; }
  const Configuration& configuration() const { return configuration_; }
  /// The last scan whose pipeline ran to its end: later scans start from it.
  std::optional<std::filesystem::path> previousScanFolder() const { return previous_; }

private:
  void registerScan(ScanUpdate& scan, const UpdateProgressCallback& progress);

  RunOptions caseOptions_;
  Configuration configuration_;
  SerialScanSession session_;
  std::optional<std::filesystem::path> previous_;
  std::vector<ScanUpdate> scans_;
  bool prepared_ = false;
  bool folderClaimed_ = false;
};

} // namespace brainshift
