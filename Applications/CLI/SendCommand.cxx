// `brainshift send`: an update's output folder to an OpenIGTLink server (a navigation system, or
// 3D Slicer's OpenIGTLinkIF connector in server mode). The work is in Logic/Interoperability.
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "OpenIGTLinkSender.h"
#include "UpdateFolder.h"
#include "VolumeIO.h"

#include <cstdio>
#include <memory>

namespace brainshift::cli {
namespace fs = std::filesystem;

void addSendCommand(CLI::App& app)
{
  struct Options {
    fs::path outputDir;
    std::string igtl;
  };
  auto options = std::make_shared<Options>();
  CLI::App* command = app.add_subcommand(
    "send", "Send an update to an OpenIGTLink server: IMAGE intraop_image and one per warped volume, TRANSFORM "
            "rigid_to_preop, POLYDATA brain_surface, then STATUS");
  command->add_option("--output-dir", options->outputDir, "the output folder of `brainshift register` (or `demo`)")
    ->required();
  command->add_option("--igtl", options->igtl, "HOST:PORT of the OpenIGTLink server (3D Slicer's default port: 18944)")
    ->required();
  command->callback([options] {
    const IgtlEndpoint endpoint = parseIgtlEndpoint(options->igtl);
    const UpdateFolderContents contents = inspectUpdateFolder(options->outputDir);
    registerIOFactories();
    OpenIGTLinkSender sender(endpoint);
    const UpdateSendSummary summary = sendUpdate(contents, sender, [](const std::string& message) {
      std::printf("sending %s\n", message.c_str());
      std::fflush(stdout);
    });
    std::printf("sent %d messages (%.1f MB) to %s in %.3f s (reading the files: %.3f s)\n", summary.messages,
                static_cast<double>(summary.bytes) / 1e6, endpoint.text().c_str(), summary.sendSeconds, summary.readSeconds);
  });
}

} // namespace brainshift::cli
