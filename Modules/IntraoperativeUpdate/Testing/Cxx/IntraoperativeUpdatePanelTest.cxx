// The surgeon's panel through a session on the small built-in case, bound to real views as the
// host binds it: the case prepared; a first scan appears in the watched folder and is updated off
// the GUI thread, its result in the scene and the views (the scan under the warped fMRI and the
// warped labels, the cursor on the strongest activation, the trust shown); a second scan with more
// shift starts from the first (its rigid start, mesh and prototypes reused); a third is cancelled
// mid-update and leaves the scene as it was; the list holds the three with their outcomes, and
// choosing the first shows it again. Bad case inputs are refused with the file named.
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftTestingSupport.h"
#include "IntraoperativeUpdatePanel.h"
#include "Scene.h"
#include "ViewLayout.h"
#include "VolumeIO.h"

#include <QApplication>
#include <QComboBox>
#include <QProgressBar>
#include <QPushButton>
#include <QLineEdit>
#include <QSignalSpy>
#include <QSurfaceFormat>
#include <QTableWidget>
#include <QTest>

#include <nlohmann/json.hpp>

#include <fstream>

namespace {
namespace fs = std::filesystem;
using namespace brainshift;

nlohmann::json reportOf(const fs::path& scanFolder)
{
  std::ifstream in(scanFolder / "report.json");
  return nlohmann::json::parse(in);
}

/// Waits (processing events) for the panel's next scanFinished; its arguments.
QList<QVariant> nextScan(QSignalSpy& finished, int before)
{
  for (int waited = 0; finished.count() <= before && waited < 240; ++waited) finished.wait(1000);
  BS_CHECK_MSG(finished.count() > before, "no scan finished within 240 s");
  return finished.at(before);
}

/// Copies `from` into the watched folder as the scanner would: written aside, then renamed.
void arrive(const fs::path& from, const fs::path& folder, const std::string& name)
{
  fs::copy_file(from, folder / (name + ".part"));
  fs::rename(folder / (name + ".part"), folder / name);
}
} // namespace

int IntraoperativeUpdatePanelTest(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  return brainshift::testing::runTest("IntraoperativeUpdatePanelTest", [] {
    const fs::path root = brainshift::testing::temporaryFolder("IntraoperativeUpdatePanelTest");
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    writeCase(simulateCase(parameters), parameters, root / "case");
    CaseParameters more = parameters;
    more.shiftMillimetres = 13;
    writeCase(simulateCase(more), more, root / "case-13mm");
    const CaseFiles files(root / "case"), moreFiles(root / "case-13mm");
    const fs::path scanner = root / "scanner";
    fs::create_directories(scanner);

    ViewLayout views;
    views.resize(700, 600);
    views.show();
    BS_CHECK(QTest::qWaitForWindowExposed(&views));
    Scene scene;
    ModuleContext context; // as the host does it, straight onto the views
    std::optional<std::array<double, 3>> cursor;
    context.showPoint = [&](const std::array<double, 3>& lps) { cursor = lps; };
    context.showLayers = [&](const ViewLayers& layers) {
      views.setBackground(std::dynamic_pointer_cast<ScalarVolumeNode>(scene.node(layers.backgroundId)));
      views.setLabelMap(std::dynamic_pointer_cast<LabelMapVolumeNode>(scene.node(layers.labelMapId)));
      views.setOverlay(std::dynamic_pointer_cast<ScalarVolumeNode>(scene.node(layers.overlayId)));
      views.setLabelOutline(layers.labelOutline);
      views.updateLayers();
    };
    IntraoperativeUpdatePanel panel(scene, context);
    BS_CHECK(panel.configurationField()->text().isEmpty());
    {
      ModuleContext configured;
      configured.configurationFile = "/cases/or-3.json";
      const IntraoperativeUpdatePanel withHostConfiguration(scene, configured); // the host's --config, offered
      BS_CHECK(withHostConfiguration.configurationField()->text() == "/cases/or-3.json");
    }
    QSignalSpy prepared(&panel, &IntraoperativeUpdatePanel::prepared);
    QSignalSpy finished(&panel, &IntraoperativeUpdatePanel::scanFinished);

    // A case whose labels do not exist is refused, naming the file; the panel stays unprepared.
    panel.setCase(QString::fromStdString(files.preopImage.string()), QString::fromStdString((root / "missing.nii.gz").string()),
                  {}, QString::fromStdString((root / "session").string()));
    panel.prepareCase();
    BS_CHECK(prepared.wait(60000));
    BS_CHECK(prepared.takeFirst().at(0).toBool() == false);
    BS_CHECK_MSG(panel.statusText().contains("missing.nii.gz"), panel.statusText().toStdString());
    BS_CHECK(!panel.isPrepared() && panel.prepareButton()->isEnabled());

    panel.setCase(QString::fromStdString(files.preopImage.string()), QString::fromStdString(files.preopLabels.string()),
                  {QString::fromStdString("fmri=" + files.preopFmri.string())}, QString::fromStdString((root / "session").string()));
    panel.prepareCase();
    BS_CHECK(prepared.wait(60000));
    BS_CHECK_MSG(prepared.takeFirst().at(0).toBool(), panel.statusText().toStdString());
    BS_CHECK(panel.isPrepared() && !panel.prepareButton()->isEnabled());

    // Scan 1 arrives in the watched folder.
    panel.setWatchFolder(QString::fromStdString(scanner.string()));
    panel.setPollMilliseconds(100);
    panel.startWatching();
    BS_CHECK(panel.isWatching());
    QSignalSpy stages(&panel, &IntraoperativeUpdatePanel::stageProgress);
    arrive(files.intraopImage, scanner, "scan-a.nii.gz");
    QList<QVariant> first = nextScan(finished, 0);
    BS_CHECK_MSG(first.at(1).toString() == "registered", first.at(1).toString().toStdString());
    BS_CHECK(first.at(2).toString() == "trusted" || first.at(2).toString() == "doubtful");
    std::set<QString> stageNames;
    for (const auto& s : stages) stageNames.insert(s.at(2).toString());
    for (const char* stage : {"rigid", "classify", "mesh", "surface", "simulate", "warp"}) BS_CHECK_MSG(stageNames.count(stage), stage);
    BS_CHECK(panel.progressBar()->value() == panel.progressBar()->maximum());
    BS_CHECK(panel.shownScan() == 1);
    const auto intraop1 = scene.findByName<ScalarVolumeNode>("intraop image");
    const auto fmri = scene.findByName<ScalarVolumeNode>("warped fmri");
    const auto labels = scene.findByName<LabelMapVolumeNode>("warped preop labels");
    BS_CHECK(intraop1 && fmri && labels && scene.findByName<ModelNode>("brain surface"));
    BS_CHECK(fs::equivalent(intraop1->storageFile(), scanner / "scan-a.nii.gz"));
    SliceView* axial = views.sliceView(SliceOrientation::Axial);
    BS_CHECK(axial->background() == intraop1);
    BS_CHECK(axial->overlay() == fmri);
    BS_CHECK(axial->labelMap() == labels);
    BS_CHECK(panel.overlayChoice()->count() == 2); // the fMRI and the confidence map
    BS_CHECK(panel.overlayChoice()->currentText() == "warped fmri");
    // The cursor on the strongest activation of the warped fMRI.
    BS_CHECK(cursor && panel.focusPoint() && *cursor == *panel.focusPoint());
    ScalarImage::PointType focus;
    for (int d = 0; d < 3; ++d) focus[d] = (*cursor)[std::size_t(d)];
    ScalarImage::IndexType at;
    BS_CHECK(fmri->image()->TransformPhysicalPointToIndex(focus, at));
    const float peak = std::fabs(fmri->image()->GetPixel(at));
    BS_CHECK(peak >= 3.0f); // an activation, not noise
    BS_CHECK(panel.trustText().contains("Scan 1") && !panel.trustText().isEmpty());

    // Scan 2, with more shift: it starts from scan 1.
    arrive(moreFiles.intraopImage, scanner, "scan-b.nii.gz");
    QList<QVariant> second = nextScan(finished, 1);
    BS_CHECK_MSG(second.at(1).toString() == "registered", second.at(1).toString().toStdString());
    const nlohmann::json report2 = reportOf(root / "session" / "scan-02");
    BS_CHECK(report2["previous_scan"].get<std::string>().find("scan-01") != std::string::npos);
    BS_CHECK(report2["stages"]["mesh"].contains("reused_from"));
    BS_CHECK(report2["stages"]["simulate"]["served"] == true && report2["stages"]["simulate"]["worker_prepared"] == false);
    BS_CHECK(panel.shownScan() == 2);
    const auto intraop2 = scene.findByName<ScalarVolumeNode>("intraop image");
    BS_CHECK(intraop2 && fs::equivalent(intraop2->storageFile(), scanner / "scan-b.nii.gz"));
    std::printf("scan 1: %.2f s, scan 2: %.2f s\n", panel.scans()[0].wallSeconds, panel.scans()[1].wallSeconds);

    // Scan 3 is cancelled as its classification starts: the scene and the views keep scan 2.
    const std::size_t nodesBefore = scene.nodes().size();
    QMetaObject::Connection cancelAtClassify =
      QObject::connect(&panel, &IntraoperativeUpdatePanel::stageProgress, &panel, [&panel](int, int, const QString& stage, const QString& message) {
        if (stage == "classify" && message.isEmpty()) panel.cancel();
      });
    arrive(files.intraopImage, scanner, "scan-c.nii.gz");
    QList<QVariant> third = nextScan(finished, 2);
    QObject::disconnect(cancelAtClassify);
    BS_CHECK_MSG(third.at(1).toString() == "cancelled", third.at(1).toString().toStdString());
    BS_CHECK(panel.trustState() == "cancelled" && panel.trustText().contains("scan 2"));
    BS_CHECK(scene.findByName<ScalarVolumeNode>("intraop image") == intraop2 && scene.nodes().size() == nodesBefore);
    BS_CHECK(axial->background() == intraop2);
    BS_CHECK(!fs::exists(root / "session" / "scan-03" / "scene.mrml"));
    BS_CHECK(panel.scanTable()->rowCount() == 3);
    BS_CHECK(panel.scanTable()->item(2, 2)->text() == "cancelled");
    BS_CHECK(!panel.isRunning());

    // The session's summary lists the three; choosing scan 1 shows it again.
    std::ifstream summaryFile(root / "session" / "watch.json");
    const nlohmann::json summary = nlohmann::json::parse(summaryFile);
    BS_CHECK(summary["scans"].size() == 3 && summary["scans"][2]["outcome"] == "cancelled");
    panel.showScan(0);
    BS_CHECK(panel.shownScan() == 1);
    const auto shownAgain = scene.findByName<ScalarVolumeNode>("intraop image");
    BS_CHECK(shownAgain && fs::equivalent(shownAgain->storageFile(), scanner / "scan-a.nii.gz"));
    BS_CHECK(axial->background() == shownAgain);
    panel.stopWatching();
    BS_CHECK(!panel.isWatching());

    // Another session in the same folder is refused, and the panel says how to replace it.
    IntraoperativeUpdatePanel another(scene, context);
    QSignalSpy anotherPrepared(&another, &IntraoperativeUpdatePanel::prepared);
    another.setCase(QString::fromStdString(files.preopImage.string()), QString::fromStdString(files.preopLabels.string()), {},
                    QString::fromStdString((root / "session").string()));
    another.prepareCase();
    BS_CHECK(anotherPrepared.wait(60000) && anotherPrepared.takeFirst().at(0).toBool() == false);
    BS_CHECK_MSG(another.statusText().contains("Replace an earlier session"), another.statusText().toStdString());
  });
}
