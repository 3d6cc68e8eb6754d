// report.json: stages merge into the file earlier stages wrote, warnings are kept once, a file
// that is not a report is refused rather than overwritten.
#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "RunReport.h"

int RunReportTest(int, char*[])
{
  return brainshift::testing::runTest("RunReportTest", [] {
    using namespace brainshift;
    namespace fs = std::filesystem;
    const fs::path folder = testing::temporaryFolder("RunReportTest");
    const fs::path file = folder / "report.json";
    {
      // A report without any stage (a run that failed on its input, or one just cleared) says so,
      // and a stage asked for is an error, not undefined behaviour.
      RunReport empty(folder / "empty.json");
      empty.clear();
      BS_CHECK(!empty.hasStage("surface"));
      BS_CHECK_THROWS(empty.stage("surface"), std::out_of_range, "surface");
    }
    {
      RunReport report(file);
      report.setStage("rigid", {{"wall_seconds", 1.5}, {"metric_value", -0.61}, {"iterations", 40}});
      report.addWarning("a warning");
      report.addWarning("a warning");
      report.save();
    }
    {
      RunReport report(file);
      BS_CHECK(report.hasStage("rigid"));
      report.setStage("mesh", {{"wall_seconds", 0.7}, {"nodes", 25800}});
      report.save();
    }
    const nlohmann::json json = nlohmann::json::parse(readTextFile(file));
    BS_CHECK_NEAR(json["stages"]["rigid"]["metric_value"].get<double>(), -0.61, 1e-12);
    BS_CHECK(json["stages"]["mesh"]["nodes"] == 25800);
    BS_CHECK(json["warnings"].size() == 1);
    BS_CHECK_THROWS(RunReport(file).setStage("warp", {{"voxels", 3}}), std::invalid_argument, "wall_seconds");
    {
      // A warning a later step overturned is withdrawn by how it begins; the others stay.
      RunReport report(file);
      report.addWarning("classify: the tumour looks resected (40 % ...)");
      report.addWarning("surface: 127 surface nodes ...");
      BS_CHECK(report.withdrawWarnings("classify: the tumour looks resected") == 1);
      BS_CHECK(report.withdrawWarnings("classify: the tumour looks resected") == 0);
      BS_CHECK(report.document()["warnings"].size() == 2);
      BS_CHECK(report.document()["warnings"][1] == "surface: 127 surface nodes ...");
      RunReport empty(folder / "no-warnings.json");
      BS_CHECK(empty.withdrawWarnings("a") == 0);
    }
    {
      // A fit done again replaces its warnings: the first fit's go, the others stay, the second's
      // are added (one said by both stays once).
      RunReport report(folder / "refit.json");
      report.replaceWarnings("surface fit", {"surface: 105 surface nodes ... left free", "surface: 6 surface triangles reversed"});
      report.addWarning("refine: the tumour ... kept in place");
      report.replaceWarnings("surface fit", {"surface: 85 surface nodes ... left free", "surface: 6 surface triangles reversed"});
      const nlohmann::json& warnings = report.document()["warnings"];
      BS_CHECK_MSG(warnings == nlohmann::json({"refine: the tumour ... kept in place", "surface: 85 surface nodes ... left free",
                                               "surface: 6 surface triangles reversed"}),
                   warnings.dump());
      report.replaceWarnings("surface fit", {});
      BS_CHECK_MSG(report.document()["warnings"] == nlohmann::json({"refine: the tumour ... kept in place"}), warnings.dump());
      // A warning another step gave before is not the fit's to withdraw, though the fit said it too.
      report.replaceWarnings("surface fit", {"refine: the tumour ... kept in place", "surface: 3 surface triangles reversed"});
      report.replaceWarnings("surface fit", {});
      BS_CHECK_MSG(report.document()["warnings"] == nlohmann::json({"refine: the tumour ... kept in place"}),
                   report.document()["warnings"].dump());
    }

    writeTextFileAtomically(folder / "broken.json", "{ not json");
    BS_CHECK_THROWS(RunReport(folder / "broken.json"), InputError, "broken.json");
    writeTextFileAtomically(folder / "list.json", "[1, 2]");
    BS_CHECK_THROWS(RunReport(folder / "list.json"), InputError, "not a BrainShift report");
  });
}
