// `brainshift export-dicom`: an update's volumes as DICOM MR series for a navigation workstation,
// and the warped labels also as a DICOM Segmentation. The work is in Logic/Interoperability.
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "DicomSeriesExport.h"
#include "UpdateFolder.h"
#include "VolumeIO.h"

#include <cstdio>
#include <memory>

namespace brainshift::cli {
namespace fs = std::filesystem;

void addExportDicomCommand(CLI::App& app)
{
  struct Options {
    fs::path outputDir, to, referenceSeries;
  };
  auto options = std::make_shared<Options>();
  CLI::App* command = app.add_subcommand(
    "export-dicom", "Write the warped volumes (and displacement magnitude, uncertainty) as DICOM MR series, and the "
                    "warped labels also as a DICOM Segmentation, sharing the intraoperative study and Frame of Reference");
  command->add_option("--output-dir", options->outputDir, "the output folder of `brainshift register` (or `demo`)")
    ->required();
  command->add_option("--to", options->to, "the folder to write the series into (one subfolder per series)")->required();
  command->add_option("--reference-series", options->referenceSeries,
                      "a DICOM series of the intraoperative scan: its patient, study and Frame of Reference are reused "
                      "(default: the intraoperative scan itself when it was a DICOM series, else new UIDs)");
  command->callback([options] {
    const UpdateFolderContents contents = inspectUpdateFolder(options->outputDir);
    registerIOFactories();
    std::optional<fs::path> reference;
    if (!options->referenceSeries.empty()) reference = options->referenceSeries;
    const DicomExportResult result = exportUpdateToDicom(contents, options->to, reference);
    for (const std::string& series : result.seriesFolders) {
      const bool segmentation = fs::exists(options->to / series / "SEG0001.dcm");
      std::printf("wrote %s%s\n", (options->to / series).c_str(), segmentation ? " (DICOM Segmentation, SEG0001.dcm)" : "");
    }
    std::printf("%zu series, %d files; study %s, Frame of Reference %s (%s)\n", result.seriesFolders.size(), result.files,
                result.study.studyInstanceUid.c_str(), result.study.frameOfReferenceUid.c_str(),
                result.fromReference ? ("from " + result.referenceSeries.string()).c_str() : "new");
  });
}

} // namespace brainshift::cli
