// brainshift watch: the operating room's way to run serial scans. Before surgery it reads and
// checks the preoperative data once; then every intraoperative scan (a list given at once, or each
// new image that appears in a folder) is registered in turn into OUT/scan-NN/, exactly as
// `register` would (every file, report.json, scene.mrml), each later scan starting from the one
// before it (register --previous) and all of them sharing what the process keeps in memory: the
// preoperative images, labels and overlays, and the served finite element worker (its partition and
// assembled matrix; each scan's fixed nodes are eliminated anew). OUT/watch.json lists the scans,
// their wall time from the image to the warped volumes, and their outcome, rewritten after each.
#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "DicomSeriesExport.h"
#include "UpdateFolder.h"
#include "OutputFolder.h"
#include "RunCommands.h"
#include "RunReport.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
#include <set>
#include <thread>

namespace brainshift::cli {
namespace fs = std::filesystem;

namespace {

struct WatchOptions {
  RunOptions run;
  std::vector<fs::path> scans; ///< --scans: registered in this order
  fs::path watchFolder;        ///< --watch-dir: new images, in name order
  unsigned maximumScans = 0;   ///< 0: until interrupted (--watch-dir), all (--scans)
  double pollSeconds = 1.0;
  fs::path exportDicom;        ///< --export-dicom: each scan's series into DIR/scan-NN/
};

/// `export-dicom` of one scan's folder; a failure is reported and kept in watch.json, never fatal.
std::string exportScanToDicom(const fs::path& scanFolder, const fs::path& target)
{
  try {
    const DicomExportResult result = exportUpdateToDicom(inspectUpdateFolder(scanFolder), target, std::nullopt);
    std::printf("== DICOM: %zu series in %s\n", result.seriesFolders.size(), target.string().c_str());
    return target.string();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "brainshift watch: DICOM export of %s: %s\n", scanFolder.string().c_str(), e.what());
    return std::string("failed: ") + e.what();
  }
}

bool isImageFile(const fs::path& path)
{
  const std::string name = path.filename().string();
  for (const char* extension : {".nii", ".nii.gz", ".nrrd", ".nhdr", ".mha", ".mhd"}) {
    const std::string e = extension;
    if (name.size() > e.size() && name.compare(name.size() - e.size(), e.size(), e) == 0) return true;
  }
  return false;
}

/// The next image of the watched folder not yet taken, once its size has stayed the same over one
/// poll (the scanner may still be writing it); empty when none is ready.
class FolderWatcher {
public:
  explicit FolderWatcher(fs::path folder)
    : folder_(std::move(folder))
  {
    std::error_code ec;
    if (!fs::is_directory(folder_, ec)) throw InputError(folder_.string() + ": --watch-dir is not a folder");
  }

  std::optional<fs::path> next()
  {
    std::error_code ec;
    std::set<fs::path> candidates;
    for (const auto& entry : fs::directory_iterator(folder_, ec)) {
      if (entry.is_regular_file(ec) && isImageFile(entry.path()) && !taken_.count(entry.path())) candidates.insert(entry.path());
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

private:
  fs::path folder_;
  std::set<fs::path> taken_;
  std::map<fs::path, std::uintmax_t> lastSize_;
};

void runWatch(const WatchOptions& o)
{
  if (o.scans.empty() == o.watchFolder.empty()) throw InputError("watch: give either --scans or --watch-dir");
  if (!(o.pollSeconds > 0 && o.pollSeconds <= 60)) throw InputError("--poll-seconds must be within 0 and 60");
  const Configuration configuration = configurationFor(o.run);
  claimOutputFolder(o.run.outputDir); // before the earlier session's check: one session per folder
  std::error_code ec;
  const fs::path summaryFile = o.run.outputDir / "watch.json";
  if (fs::exists(summaryFile, ec)) { // an earlier session's scans: kept unless told otherwise
    if (!o.run.overwrite) {
      throw InputError(o.run.outputDir.string() + ": holds an earlier watch session (watch.json); choose another --output-dir, "
                       "or pass --overwrite to replace its scans");
    }
    for (const auto& entry : fs::directory_iterator(o.run.outputDir, ec)) {
      if (entry.is_directory(ec) && entry.path().filename().string().rfind("scan-", 0) == 0) fs::remove_all(entry.path(), ec);
    }
    fs::remove(summaryFile, ec);
  }
  fs::create_directories(o.run.outputDir, ec);
  if (ec) throw InputError(o.run.outputDir.string() + ": cannot create the output folder (" + ec.message() + ")");
  std::unique_ptr<FolderWatcher> watcher;
  if (!o.watchFolder.empty()) watcher = std::make_unique<FolderWatcher>(o.watchFolder);

  SerialScanSession session;
  nlohmann::json summary = {{"preop_image", fs::absolute(o.run.preopImage).string()},
                            {"preop_labels", fs::absolute(o.run.preopLabels).string()},
                            {"scans", nlohmann::json::array()}};
  fs::path previous;
  std::size_t failures = 0;
  std::size_t listed = 0;
  const unsigned limit = o.maximumScans > 0 ? o.maximumScans : (watcher ? 0u : unsigned(o.scans.size()));
  for (unsigned number = 1; limit == 0 || number <= limit; ++number) {
    fs::path image;
    if (watcher) {
      std::optional<fs::path> found;
      while (!(found = watcher->next())) std::this_thread::sleep_for(std::chrono::duration<double>(o.pollSeconds));
      image = *found;
    } else {
      if (listed >= o.scans.size()) break;
      image = o.scans[listed++];
    }
    char folderName[32];
    std::snprintf(folderName, sizeof folderName, "scan-%02u", number);
    RunOptions run = o.run;
    run.intraopImage = image;
    run.outputDir = o.run.outputDir / folderName;
    run.previous = previous;
    run.overwrite = true; // the session's own folders (an earlier session's were removed above)
    fs::create_directories(run.outputDir, ec);
    std::printf("== scan %u: %s -> %s\n", number, image.string().c_str(), run.outputDir.string().c_str());
    std::fflush(stdout);
    nlohmann::json entry = {{"scan", number}, {"intraop_image", fs::absolute(image).string()}, {"output_dir", run.outputDir.string()}};
    const auto start = std::chrono::steady_clock::now();
    try {
      RunReport report(run.outputDir / "report.json");
      report.clear(); // a scan folder of an earlier session is replaced
      RunContext context(run, configuration, report);
      context.joinSession(session);
      runRegistration(context);
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      report.set("scan_wall_seconds", seconds);
      report.save();
      entry["wall_seconds"] = seconds;
      entry["outcome"] = "registered";
      nlohmann::json stages = nlohmann::json::object();
      for (const auto& [stage, values] : report.document()["stages"].items()) stages[stage] = values.value("wall_seconds", 0.0);
      entry["stage_seconds"] = stages;
      previous = run.outputDir;
      ++session.scans;
      std::printf("== scan %u registered in %.2f s\n", number, seconds);
      if (!o.exportDicom.empty()) entry["dicom"] = exportScanToDicom(run.outputDir, o.exportDicom / folderName);
    } catch (const std::exception& e) { // one scan's failure does not end the watch
      ++failures;
      entry["wall_seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      entry["outcome"] = std::string("failed: ") + e.what();
      std::fprintf(stderr, "brainshift watch: scan %u (%s): %s\n", number, image.string().c_str(), e.what());
    }
    std::fflush(stdout);
    summary["scans"].push_back(entry);
    writeTextFileAtomically(summaryFile, summary.dump(2) + "\n");
  }
  if (failures > 0) {
    throw MethodError(std::to_string(failures) + " of " + std::to_string(summary["scans"].size()) + " scans failed (see " +
                      summaryFile.string() + ")");
  }
}

} // namespace

void addWatchCommand(CLI::App& app)
{
  auto o = std::make_shared<WatchOptions>();
  CLI::App* command = app.add_subcommand(
    "watch", "Serial scans in one session: the preoperative data read once, each intraoperative scan (--scans, or each new image "
             "in --watch-dir) registered in turn into OUT/scan-NN/, later ones reusing the earlier ones' work and a served "
             "finite element worker");
  addRunOptions(command, o->run, unsigned(InputFlag::PreopImage) | unsigned(InputFlag::PreopLabels),
                unsigned(InputFlag::PreopImage) | unsigned(InputFlag::PreopLabels) | unsigned(InputFlag::Overlays), true, true, true);
  command->add_option("--scans", o->scans, "intraoperative images, registered in this order")->delimiter(',');
  command->add_option("--watch-dir", o->watchFolder, "a folder the scanner writes images into; each new one is registered");
  command->add_option("--max-scans", o->maximumScans, "stop after this many scans (default: all listed, or never)");
  command->add_option("--poll-seconds", o->pollSeconds, "how often --watch-dir is looked at")->capture_default_str();
  command->add_option("--export-dicom", o->exportDicom,
                      "after each scan, its series as `export-dicom` writes them into DIR/scan-NN/");
  command->add_flag("--overwrite", o->run.overwrite, "replace an earlier watch session's scans in --output-dir");
  command->callback([o] { runWatch(*o); });
}

} // namespace brainshift::cli
