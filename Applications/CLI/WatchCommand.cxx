// brainshift watch: the operating room's way to run serial scans. Before surgery it reads and
// checks the preoperative data once; then every intraoperative scan (a list given at once, or each
// new image that appears in a folder) is registered in turn into OUT/scan-NN/, exactly as
// `register` would (every file, report.json, scene.mrml), each later scan starting from the one
// before it (register --previous) and all of them sharing what the process keeps in memory: the
// preoperative images, labels and overlays, and the served finite element worker (its partition and
// assembled matrix; each scan's fixed nodes are eliminated anew). OUT/watch.json lists the scans,
// their wall time from the image to the warped volumes, and their outcome, rewritten after each.
// With --igtl-server an OpenIGTLink server (Logic/Interoperability/OpenIGTLinkServer, its own thread)
// pushes each update to the navigation side and hands over scans sent as IMAGE intraop; the
// registrations stay on this thread.
#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "DicomSeriesExport.h"
#include "OpenIGTLinkSender.h"
#include "OpenIGTLinkServer.h"
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
  std::string igtlServer;      ///< --igtl-server [ADDRESS:]PORT: push each update, take IMAGE intraop as scans
};

/// "[ADDRESS:]PORT" of --igtl-server; every address of this machine when none is given.
IgtlEndpoint parseServerAddress(const std::string& text)
{
  const bool withAddress = text.find(':') != std::string::npos;
  try {
    IgtlEndpoint endpoint = parseIgtlEndpoint(withAddress ? text : "0.0.0.0:" + text);
    if (!withAddress) endpoint.host.clear();
    return endpoint;
  } catch (const InputError&) {
    throw InputError("--igtl-server " + text + ": expected [ADDRESS:]PORT with a port from 1 to 65535, e.g. 18944 or 127.0.0.1:18944");
  }
}

/// The OpenIGTLink server of a session, its events for watch.json.
std::unique_ptr<OpenIGTLinkServer> startIgtlServer(const std::string& text, const fs::path& receiveFolder)
{
  const IgtlEndpoint endpoint = parseServerAddress(text);
  auto server = std::make_unique<OpenIGTLinkServer>(endpoint.host, endpoint.port, receiveFolder, [](const IgtlServerEvent& e) {
    if (e.event == "dropped" || e.event == "refused message") {
      std::fprintf(stderr, "brainshift watch: OpenIGTLink client %s %s: %s\n", e.client.c_str(), e.event.c_str(), e.detail.c_str());
    } else {
      std::printf("== OpenIGTLink client %s %s: %s\n", e.client.c_str(), e.event.c_str(), e.detail.c_str());
      std::fflush(stdout);
    }
  });
  std::printf("== OpenIGTLink server listening on %s:%d\n", endpoint.host.empty() ? "0.0.0.0" : endpoint.host.c_str(),
              server->port());
  std::fflush(stdout);
  return server;
}

nlohmann::json igtlServerSummary(const OpenIGTLinkServer& server)
{
  nlohmann::json events = nlohmann::json::array();
  for (const IgtlServerEvent& e : server.events()) events.push_back({{"client", e.client}, {"event", e.event}, {"detail", e.detail}});
  return {{"port", server.port()}, {"events", events}};
}

/// Packs scan's update once and hands it to the server, which pushes it to every client; a failure
/// is reported and kept in watch.json, never fatal.
std::string pushUpdate(OpenIGTLinkServer& server, const fs::path& scanFolder)
{
  try {
    std::vector<PackedIgtlMessage> messages;
    OpenIGTLinkSender recorder(messages);
    sendUpdate(inspectUpdateFolder(scanFolder), recorder);
    const std::size_t count = messages.size();
    server.publish(std::move(messages));
    std::printf("== OpenIGTLink: %zu messages pushed to the clients\n", count);
    return "pushed " + std::to_string(count) + " messages";
  } catch (const std::exception& e) {
    std::fprintf(stderr, "brainshift watch: OpenIGTLink update of %s: %s\n", scanFolder.string().c_str(), e.what());
    return std::string("failed: ") + e.what();
  }
}

/// A failed scan's STATUS (error) to the connected clients; the latest update stays the last good one.
void pushFailure(OpenIGTLinkServer& server, unsigned number, const std::string& reason)
{
  std::vector<PackedIgtlMessage> messages;
  OpenIGTLinkSender recorder(messages);
  recorder.sendStatus("brainshift", false, "BrainShift scan " + std::to_string(number) + " failed: " + reason);
  server.publish(std::move(messages), false);
}

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

/// Where the session's scans come from: the --scans list first, then each new image of --watch-dir
/// and each IMAGE intraop a client sends, whichever comes first.
class ScanSource {
public:
  ScanSource(const WatchOptions& o, OpenIGTLinkServer* server)
    : scans_(o.scans), server_(server), pollSeconds_(o.pollSeconds)
  {
    if (!o.watchFolder.empty()) watcher_ = std::make_unique<FolderWatcher>(o.watchFolder);
  }
  /// Whether the session goes on after the list (until --max-scans or an interruption).
  bool waits() const { return watcher_ || server_; }
  /// The next image and where it came from; none when the list is done and nothing else is watched.
  std::optional<std::pair<fs::path, std::string>> next()
  {
    if (listed_ < scans_.size()) return std::make_pair(scans_[listed_++], std::string("--scans"));
    while (waits()) {
      if (watcher_) {
        if (auto found = watcher_->next()) return std::make_pair(*found, std::string("--watch-dir"));
      }
      if (server_) {
        if (auto scan = server_->nextScan(pollSeconds_)) return std::make_pair(scan->file, "OpenIGTLink client " + scan->client);
      } else {
        std::this_thread::sleep_for(std::chrono::duration<double>(pollSeconds_));
      }
    }
    return std::nullopt;
  }

private:
  std::vector<fs::path> scans_;
  std::size_t listed_ = 0;
  std::unique_ptr<FolderWatcher> watcher_;
  OpenIGTLinkServer* server_;
  double pollSeconds_;
};

/// Claims --output-dir for the session; an earlier session's scans are removed with --overwrite.
void prepareSessionFolder(const RunOptions& run, const fs::path& summaryFile)
{
  claimOutputFolder(run.outputDir); // before the earlier session's check: one session per folder
  std::error_code ec;
  if (fs::exists(summaryFile, ec)) { // an earlier session's scans: kept unless told otherwise
    if (!run.overwrite) {
      throw InputError(run.outputDir.string() + ": holds an earlier watch session (watch.json); choose another --output-dir, "
                       "or pass --overwrite to replace its scans");
    }
    for (const auto& entry : fs::directory_iterator(run.outputDir, ec)) {
      const std::string name = entry.path().filename().string();
      if (entry.is_directory(ec) && (name.rfind("scan-", 0) == 0 || name == "received")) fs::remove_all(entry.path(), ec);
    }
    fs::remove(summaryFile, ec);
  }
  fs::create_directories(run.outputDir, ec);
  if (ec) throw InputError(run.outputDir.string() + ": cannot create the output folder (" + ec.message() + ")");
}

struct ScanResult {
  nlohmann::json entry;
  bool registered = false;
};

/// The trust assessment's verdict on a scan's non-rigid update ("trusted", "doubtful", "rejected":
/// the rigid result stands), or "not assessed" when the update did not get that far.
std::string trustOf(const fs::path& scanFolder)
{
  try {
    const nlohmann::json report = nlohmann::json::parse(readTextFile(scanFolder / "report.json"));
    if (report.contains("trust") && report["trust"].contains("nonrigid")) return report["trust"]["nonrigid"].get<std::string>();
  } catch (const std::exception&) {
  }
  return "not assessed";
}

/// Registers one scan into run.outputDir as `register --previous` would.
ScanResult registerScan(const RunOptions& run, const Configuration& configuration, SerialScanSession& session, unsigned number)
{
  ScanResult result;
  result.entry = {{"scan", number}, {"intraop_image", fs::absolute(run.intraopImage).string()}, {"output_dir", run.outputDir.string()}};
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
    result.entry["wall_seconds"] = seconds;
    result.entry["outcome"] = "registered";
    nlohmann::json stages = nlohmann::json::object();
    for (const auto& [stage, values] : report.document()["stages"].items()) stages[stage] = values.value("wall_seconds", 0.0);
    result.entry["stage_seconds"] = stages;
    result.entry["trust"] = trustOf(run.outputDir);
    result.registered = true;
    std::printf("== scan %u registered in %.2f s; the non-rigid update is %s\n", number, seconds,
                result.entry["trust"].get<std::string>().c_str());
  } catch (const std::exception& e) { // one scan's failure does not end the watch
    result.entry["wall_seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    result.entry["outcome"] = std::string("failed: ") + e.what();
    // A rejected update has left the rigid result in every file: the surgeon must see which it is.
    result.entry["trust"] = trustOf(run.outputDir);
    std::fprintf(stderr, "brainshift watch: scan %u (%s): %s\n", number, run.intraopImage.string().c_str(), e.what());
  }
  return result;
}

void runWatch(const WatchOptions& o)
{
  if (!o.scans.empty() && !o.watchFolder.empty()) throw InputError("watch: give either --scans or --watch-dir, not both");
  if (o.scans.empty() && o.watchFolder.empty() && o.igtlServer.empty()) {
    throw InputError("watch: give either --scans or --watch-dir, or --igtl-server alone (scans sent as IMAGE intraop)");
  }
  if (!(o.pollSeconds > 0 && o.pollSeconds <= 60)) throw InputError("--poll-seconds must be within 0 and 60");
  if (!o.igtlServer.empty()) parseServerAddress(o.igtlServer); // bad input before any work
  const Configuration configuration = configurationFor(o.run);
  const fs::path summaryFile = o.run.outputDir / "watch.json";
  prepareSessionFolder(o.run, summaryFile);
  std::unique_ptr<OpenIGTLinkServer> server;
  if (!o.igtlServer.empty()) server = startIgtlServer(o.igtlServer, o.run.outputDir / "received");
  ScanSource source(o, server.get());

  SerialScanSession session;
  nlohmann::json summary = {{"preop_image", fs::absolute(o.run.preopImage).string()},
                            {"preop_labels", fs::absolute(o.run.preopLabels).string()},
                            {"scans", nlohmann::json::array()}};
  const auto saveSummary = [&] {
    if (server) summary["igtl_server"] = igtlServerSummary(*server);
    writeTextFileAtomically(summaryFile, summary.dump(2) + "\n");
  };
  fs::path previous;
  std::size_t failures = 0;
  const unsigned limit = o.maximumScans > 0 ? o.maximumScans : (source.waits() ? 0u : unsigned(o.scans.size()));
  for (unsigned number = 1; limit == 0 || number <= limit; ++number) {
    const auto next = source.next();
    if (!next) break;
    char folderName[32];
    std::snprintf(folderName, sizeof folderName, "scan-%02u", number);
    RunOptions run = o.run;
    run.intraopImage = next->first;
    run.outputDir = o.run.outputDir / folderName;
    run.previous = previous;
    run.overwrite = true; // the session's own folders (an earlier session's were removed above)
    std::error_code ec;
    fs::create_directories(run.outputDir, ec);
    std::printf("== scan %u: %s (%s) -> %s\n", number, next->first.string().c_str(), next->second.c_str(),
                run.outputDir.string().c_str());
    std::fflush(stdout);
    ScanResult result = registerScan(run, configuration, session, number);
    result.entry["source"] = next->second;
    if (result.registered) {
      previous = run.outputDir;
      ++session.scans;
      if (server) result.entry["igtl"] = pushUpdate(*server, run.outputDir);
      if (!o.exportDicom.empty()) result.entry["dicom"] = exportScanToDicom(run.outputDir, o.exportDicom / folderName);
    } else {
      ++failures;
      if (server) pushFailure(*server, number, result.entry["outcome"].get<std::string>());
    }
    std::fflush(stdout);
    summary["scans"].push_back(result.entry);
    saveSummary();
  }
  if (server) {
    server->close(); // the last update pushed, the connections closed: every client's fate is known
    saveSummary();
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
  command->add_option("--igtl-server", o->igtlServer,
                      "[ADDRESS:]PORT: an OpenIGTLink server for the session (3D Slicer's OpenIGTLinkIF in client mode, a "
                      "navigation system): each scan's update is pushed to every client as `send` sends it, and an IMAGE "
                      "`intraop` a client sends is registered as a new scan");
  command->add_flag("--overwrite", o->run.overwrite, "replace an earlier watch session's scans in --output-dir");
  command->callback([o] { runWatch(*o); });
}

} // namespace brainshift::cli
