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
#include "IntraoperativeUpdateLogic.h"
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

/// Where the session's scans come from: the --scans list first, then each new image of --watch-dir
/// and each IMAGE intraop a client sends, whichever comes first.
class ScanSource {
public:
  ScanSource(const WatchOptions& o, OpenIGTLinkServer* server)
    : scans_(o.scans), server_(server), pollSeconds_(o.pollSeconds)
  {
    if (!o.watchFolder.empty()) watcher_ = std::make_unique<ScanFolderWatcher>(o.watchFolder);
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
  std::unique_ptr<ScanFolderWatcher> watcher_;
  OpenIGTLinkServer* server_;
  double pollSeconds_;
};

void runWatch(const WatchOptions& o)
{
  if (!o.scans.empty() && !o.watchFolder.empty()) throw InputError("watch: give either --scans or --watch-dir, not both");
  if (o.scans.empty() && o.watchFolder.empty() && o.igtlServer.empty()) {
    throw InputError("watch: give either --scans or --watch-dir, or --igtl-server alone (scans sent as IMAGE intraop)");
  }
  if (!(o.pollSeconds > 0 && o.pollSeconds <= 60)) throw InputError("--poll-seconds must be within 0 and 60");
  if (!o.igtlServer.empty()) parseServerAddress(o.igtlServer); // bad input before any work
  std::error_code ec;
  if (!o.watchFolder.empty() && !fs::is_directory(o.watchFolder, ec)) throw InputError(o.watchFolder.string() + ": --watch-dir is not a folder");
  IntraoperativeUpdateLogic session(o.run); // the configuration checked before anything is written
  session.claimSessionFolder();
  // The navigation side may connect while the case is being prepared.
  std::unique_ptr<OpenIGTLinkServer> server;
  if (!o.igtlServer.empty()) server = startIgtlServer(o.igtlServer, o.run.outputDir / "received");
  session.prepare(); // the preoperative data read and checked once, the mesh, the boundary, the worker: before the first scan
  ScanSource source(o, server.get());
  const auto extra = [&] { return server ? nlohmann::json{{"igtl_server", igtlServerSummary(*server)}} : nlohmann::json::object(); };

  std::size_t failures = 0;
  const unsigned limit = o.maximumScans > 0 ? o.maximumScans : (source.waits() ? 0u : unsigned(o.scans.size()));
  for (unsigned number = 1; limit == 0 || number <= limit; ++number) {
    const auto next = source.next();
    if (!next) break;
    std::printf("== scan %u: %s (%s) -> %s/scan-%02u\n", number, next->first.string().c_str(), next->second.c_str(),
                o.run.outputDir.string().c_str(), number);
    std::fflush(stdout);
    const ScanUpdate scan = session.update(next->first, next->second);
    ScanUpdate& kept = session.lastScan();
    if (scan.registered) {
      std::printf("== scan %u registered in %.2f s; the non-rigid update is %s\n", number, scan.wallSeconds, scan.trust.c_str());
      if (server) kept.entry["igtl"] = pushUpdate(*server, scan.outputDir);
      if (!o.exportDicom.empty()) kept.entry["dicom"] = exportScanToDicom(scan.outputDir, o.exportDicom / scan.outputDir.filename());
    } else {
      ++failures;
      std::fprintf(stderr, "brainshift watch: scan %u (%s): %s\n", number, next->first.string().c_str(), scan.failure.c_str());
      if (server) pushFailure(*server, number, scan.outcome);
    }
    std::fflush(stdout);
    session.saveSummary(extra());
  }
  if (server) {
    server->close(); // the last update pushed, the connections closed: every client's fate is known
    session.saveSummary(extra());
  }
  if (failures > 0) {
    throw MethodError(std::to_string(failures) + " of " + std::to_string(session.scans().size()) + " scans failed (see " +
                      session.summaryFile().string() + ")");
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
