// The intraoperative update as the logic runs it (IntraoperativeUpdateLogic), against the command
// line on the same small built-in case: the same rigid transform and the same displacement field
// (to the solver's run-to-run rounding); the stages reported in pipeline order to the progress
// callback, with their lines; a session refused before surgery when its labels cannot be read
// (the file named); an unreadable scan failing alone while the next registers from the last good
// one; a cancel before the solve stopping the scan with nothing of it used later.
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "IntraoperativeUpdateLogic.h"
#include "TransformIO.h"
#include "VolumeIO.h"

#include <itkImageRegionConstIterator.h>
#include <itkMatrixOffsetTransformBase.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <thread>

namespace {
namespace fs = std::filesystem;
using namespace brainshift;

double largestDifferenceMm(const DisplacementFieldImage& a, const DisplacementFieldImage& b)
{
  BS_CHECK(a.GetLargestPossibleRegion() == b.GetLargestPossibleRegion());
  itk::ImageRegionConstIterator<DisplacementFieldImage> ia(&a, a.GetLargestPossibleRegion()), ib(&b, b.GetLargestPossibleRegion());
  double largest = 0;
  for (; !ia.IsAtEnd(); ++ia, ++ib) {
    for (unsigned d = 0; d < 3; ++d) largest = std::max(largest, double(std::fabs(ia.Get()[d] - ib.Get()[d])));
  }
  return largest;
}

nlohmann::json reportOf(const fs::path& folder)
{
  std::ifstream in(folder / "report.json");
  return nlohmann::json::parse(in);
}
} // namespace

int IntraoperativeUpdateLogicTest(int, char*[])
{
  return brainshift::testing::runTest("IntraoperativeUpdateLogicTest", [] {
    const fs::path root = brainshift::testing::temporaryFolder("IntraoperativeUpdateLogicTest");
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    writeCase(simulateCase(parameters), parameters, root / "case");
    const CaseFiles files(root / "case");

    RunOptions caseOptions;
    caseOptions.preopImage = files.preopImage;
    caseOptions.preopLabels = root / "missing_labels.nii.gz";
    caseOptions.outputDir = root / "refused";
    {
      IntraoperativeUpdateLogic refused(caseOptions);
      BS_CHECK_THROWS(refused.prepare(), InputError, "missing_labels.nii.gz");
      BS_CHECK(!refused.prepared());
    }
    caseOptions.preopLabels = files.preopLabels;
    caseOptions.overlays = {"fmri=" + files.preopFmri.string()};
    caseOptions.outputDir = root / "session";
    IntraoperativeUpdateLogic session(caseOptions);
    session.prepare();

    // Scan 1, reported stage by stage.
    std::vector<std::string> started;
    std::size_t lines = 0;
    const ScanUpdate first = session.update(files.intraopImage, "test", [&](const UpdateProgress& step) {
      if (step.message.empty()) started.push_back(step.stage);
      else ++lines;
      BS_CHECK(step.count == pipelineStages().size() && step.index < step.count);
    });
    BS_CHECK_MSG(first.registered, first.outcome);
    BS_CHECK(first.outcome == "registered" && first.failure.empty() && first.number == 1 && first.outputDir == root / "session" / "scan-01");
    std::vector<std::string> expected;
    for (const PipelineStage& stage : pipelineStages()) expected.push_back(stage.name);
    BS_CHECK(started == expected);
    BS_CHECK(lines >= expected.size()); // each stage says what it did
    BS_CHECK(first.trust == "trusted" || first.trust == "doubtful");
    BS_CHECK(first.stageSeconds.size() == expected.size());

    // The command line on the same case: `watch` (a session as this one) gives the same result, to
    // the solver's run-to-run rounding; `register` (a one-shot solve, its own worker and solver
    // defaults) the same rigid transform and the field to the iterative solver's tolerance.
    const auto run = [&](const std::string& subcommand, const std::string& intraop, const fs::path& folder) {
      const std::string command = std::string(BRAINSHIFT_EXECUTABLE) + " " + subcommand + " --preop-image " + files.preopImage.string() +
                                  " --preop-labels " + files.preopLabels.string() + " --overlay fmri=" + files.preopFmri.string() + " " +
                                  intraop + " --output-dir " + folder.string() + " > " + folder.string() + ".log 2>&1";
      BS_CHECK_MSG(std::system(command.c_str()) == 0, "brainshift " + subcommand + " failed: see " + folder.string() + ".log");
    };
    run("watch", "--scans " + files.intraopImage.string(), root / "watch");
    run("register", "--intraop-image " + files.intraopImage.string(), root / "register");
    const auto rigidLogic = readTransform(first.outputDir / "rigid_intraop_to_preop.tfm");
    const auto fieldLogic = readDisplacementField(first.outputDir / "displacement_intraop_to_preop.nrrd");
    for (const fs::path& byCommandLine : {root / "watch" / "scan-01", root / "register"}) {
      const auto rigidCommandLine = readTransform(byCommandLine / "rigid_intraop_to_preop.tfm");
      const auto pl = rigidLogic->GetParameters(), pc = rigidCommandLine->GetParameters();
      BS_CHECK(pl.Size() == pc.Size());
      for (unsigned i = 0; i < pl.Size(); ++i) BS_CHECK_NEAR(pl[i], pc[i], 1e-9);
      const double difference = largestDifferenceMm(*fieldLogic, *readDisplacementField(byCommandLine / "displacement_intraop_to_preop.nrrd"));
      const bool session = byCommandLine.filename() == "scan-01";
      std::printf("largest field difference, logic against %s: %.2e mm\n", session ? "watch" : "register", difference);
      BS_CHECK(difference < (session ? 2e-3 : 1e-2)); // two runs of the same session differed by up to 3e-4 mm here
    }

    // An unreadable scan fails alone; the next starts from scan 1.
    const fs::path broken = root / "broken.nii";
    std::ofstream(broken) << "not an image";
    const ScanUpdate failed = session.update(broken, "test");
    BS_CHECK(!failed.registered && failed.outcome.rfind("failed: ", 0) == 0 && failed.outcome.find("broken.nii") != std::string::npos &&
             failed.outcome == "failed: " + failed.failure);
    BS_CHECK(failed.trust == "not assessed");
    BS_CHECK(session.previousScanFolder() == first.outputDir);

    // A cancel as the classification starts: the scan stops there, and is not used later.
    const ScanUpdate cancelled = session.update(files.intraopImage, "test", [&](const UpdateProgress& step) {
      if (step.stage == "classify" && step.message.empty()) session.cancel();
    });
    BS_CHECK_MSG(cancelled.cancelled && cancelled.outcome == "cancelled" && cancelled.failure == "cancelled", cancelled.outcome);
    BS_CHECK(!fs::exists(cancelled.outputDir / "scene.mrml"));
    BS_CHECK(session.previousScanFolder() == first.outputDir);

    const ScanUpdate later = session.update(files.intraopImage, "test");
    BS_CHECK_MSG(later.registered, later.outcome);
    BS_CHECK(later.number == 4);
    const nlohmann::json report = reportOf(later.outputDir);
    BS_CHECK(report["previous_scan"].get<std::string>().find("scan-01") != std::string::npos);
    BS_CHECK(report["stages"]["mesh"].contains("reused_from"));

    std::ifstream summaryFile(session.summaryFile());
    const nlohmann::json summary = nlohmann::json::parse(summaryFile);
    BS_CHECK(summary["scans"].size() == 4);
    BS_CHECK(summary["scans"][2]["outcome"] == "cancelled" && summary["scans"][3]["outcome"] == "registered");

    // A second session in the same folder is refused unless it replaces the first.
    IntraoperativeUpdateLogic again(caseOptions);
    BS_CHECK_THROWS(again.prepare(), InputError, "earlier watch session");
  });
}
