// The host runs the surgeon's session: the "Intraoperative update" module loaded as a plugin,
// driven as brainshift-host's command line drives it (ScriptedSession), prepares the small
// built-in case and updates it with two scans in turn; the host's scene then holds the second
// scan's result and the host's views show the scan with the warped fMRI and labels over it.
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftTestingSupport.h"
#include "HostMainWindow.h"
#include "ScriptedSession.h"

#include <QApplication>
#include <QSignalSpy>
#include <QSurfaceFormat>
#include <QTest>

#include <nlohmann/json.hpp>

#include <fstream>

int HostUpdateSessionTest(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  return brainshift::testing::runTest("HostUpdateSessionTest", [] {
    using namespace brainshift;
    namespace fs = std::filesystem;
    const fs::path root = testing::temporaryFolder("HostUpdateSessionTest");
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    writeCase(simulateCase(parameters), parameters, root / "case");
    // The first scan at 7 mm: at 5 mm the small case's own update (0.54 mm against 0.73 rigid) is
    // one of the trust assessment's false rejections since the field carries the correction across
    // the brain's boundary (README, "Whether the update can be trusted"), a question this test of
    // the host's session is not about.
    CaseParameters early = parameters;
    early.shiftMillimetres = 7;
    writeCase(simulateCase(early), early, root / "early");
    const CaseFiles files(root / "case"), earlyFiles(root / "early");

    HostMainWindow host(defaultModulesFolder());
    host.resize(1200, 800);
    host.show();
    BS_CHECK(QTest::qWaitForWindowExposed(&host));
    BS_CHECK(host.selectModule("Intraoperative update"));
    QWidget* panel = host.currentPanel();
    BS_CHECK(panel && QString(panel->metaObject()->className()) == "brainshift::IntraoperativeUpdatePanel");
    auto q = [](const fs::path& p) { return QString::fromStdString(p.string()); };
    QMetaObject::invokeMethod(panel, "setCase", Q_ARG(QString, q(files.preopImage)), Q_ARG(QString, q(files.preopLabels)),
                              Q_ARG(QStringList, QStringList{"fmri=" + q(files.preopFmri)}), Q_ARG(QString, q(root / "session")),
                              Q_ARG(QString, QString()));
    int ended = 0;
    bool ok = false;
    new ScriptedSession(panel, {q(earlyFiles.intraopImage), q(files.intraopImage)}, [&](bool allRegistered) {
      ++ended;
      ok = allRegistered;
    });
    QMetaObject::invokeMethod(panel, "prepareCase");
    for (int waited = 0; ended == 0 && waited < 2400; ++waited) QTest::qWait(100);
    BS_CHECK_MSG(ended == 1 && ok, panel->property("statusText").toString().toStdString());
    QTest::qWait(500); // the other panels follow the new scene too (the fusion panel picks its layers by role)

    std::ifstream summaryFile(root / "session" / "watch.json");
    const nlohmann::json summary = nlohmann::json::parse(summaryFile);
    BS_CHECK(summary["scans"].size() == 2);
    for (const auto& scan : summary["scans"]) BS_CHECK(scan["outcome"] == "registered");
    const QString trust = panel->property("trustState").toString();
    BS_CHECK_MSG(trust == "trusted" || trust == "doubtful", trust.toStdString());

    const auto intraop = host.scene().findByName<ScalarVolumeNode>("intraop image");
    const auto fmri = host.scene().findByName<ScalarVolumeNode>("warped fmri");
    const auto labels = host.scene().findByName<LabelMapVolumeNode>("warped preop labels");
    BS_CHECK(intraop && fmri && labels && host.scene().findByName<ModelNode>("brain surface"));
    BS_CHECK(fs::equivalent(intraop->storageFile(), files.intraopImage));
    SliceView& axial = *host.views()->sliceView(SliceOrientation::Axial);
    BS_CHECK(axial.background() == intraop);
    BS_CHECK_MSG(axial.overlay() == fmri, axial.overlay() ? axial.overlay()->name() : "no overlay");
    BS_CHECK(axial.labelMap() == labels);
  });
}
