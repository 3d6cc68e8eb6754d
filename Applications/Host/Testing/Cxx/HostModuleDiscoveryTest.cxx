// The host finds the modules in the modules folder; a file that is not a plugin, a module whose
// panel throws and a missing folder are reported, and the host starts all the same.
#include "BrainShiftTestingSupport.h"
#include "DataPanel.h"
#include "HostMainWindow.h"

#include "SyntheticData.h"

#include <itkIdentityTransform.h>

#include <QApplication>
#include <QComboBox>
#include <QPushButton>
#include <QTableWidget>
#include <QFile>
#include <QLabel>
#include <QSurfaceFormat>

#include <fstream>

int HostModuleDiscoveryTest(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  return brainshift::testing::runTest("HostModuleDiscoveryTest", [] {
    using namespace brainshift;
    // The build's modules folder ($BRAINSHIFT_MODULES_DIR, set by the test).
    {
      HostMainWindow host(defaultModulesFolder());
      BS_CHECK_MSG(host.moduleFailures().empty(), host.lastMessage().toStdString());
      BS_CHECK_MSG(host.moduleTitles() == QStringList({"Data", "Intraoperative update", "Rigid registration", "Tissue classification", "Meshing",
                                                            "Surface and simulation", "Fusion and review", "Evaluation"}),
                   host.moduleTitles().join(", ").toStdString());

      // A module panel reaches the views through the host's context: a click on a landmark's
      // row in the evaluation table moves the linked cursor to the landmark.
      auto identity = itk::IdentityTransform<double, 3>::New();
      host.scene().add(TransformNode::create("identity", identity.GetPointer()));
      host.scene().add(LandmarksNode::create("landmarks", {{"brain-01", testing::point(1, 2, 3), testing::point(4, 5, 6)}}));
      BS_CHECK(host.selectModule("Evaluation"));
      auto* evaluate = host.currentPanel()->findChild<QPushButton*>("evaluateButton");
      auto* table = host.currentPanel()->findChild<QTableWidget*>("errorTable");
      BS_CHECK(evaluate && table);
      evaluate->click();
      BS_CHECK(table->rowCount() == 1);
      emit table->cellClicked(0, 1);
      BS_CHECK(host.views()->cursorPosition() == testing::point(4, 5, 6));

      // Points picked in a slice view reach a panel that subscribed: with Pick on, the tissue
      // classification panel lists a prototype; moving the cursor from code does not pick.
      BS_CHECK(host.selectModule("Tissue classification"));
      auto* pickButton = host.currentPanel()->findChild<QPushButton*>("pickButton");
      auto* counts = host.currentPanel()->findChild<QLabel*>("prototypeCounts");
      BS_CHECK(pickButton && counts && pickButton->isEnabled());
      pickButton->setChecked(true);
      host.views()->setCursorPosition(testing::point(1, 1, 1));
      BS_CHECK(counts->text().startsWith("None"));
      emit host.views()->sliceView(SliceOrientation::Coronal)->cursorPicked(testing::point(2, 2, 2));
      BS_CHECK_MSG(counts->text().contains("1 picked"), counts->text().toStdString());
      BS_CHECK(host.views()->cursorPosition() == testing::point(2, 2, 2));

      // The fusion panel sets the views' layers through the host's Data panel.
      auto intraop = host.scene().add(ScalarVolumeNode::create("intraop image", testing::makeUniformImage({20, 20, 20}, 100.0f)));
      intraop->setRole("intraop");
      auto tmap = host.scene().add(ScalarVolumeNode::create("warped fmri", testing::makeUniformImage({20, 20, 20}, 5.0f)));
      tmap->setRole("overlay");
      BS_CHECK(host.selectModule("Fusion and review"));
      // (The plugin has its own copy of the Widgets classes: reach its selector as a QComboBox.)
      auto* intraopSelector = host.currentPanel()->findChild<QComboBox*>("intraopSelector");
      BS_CHECK(intraopSelector && intraopSelector->findText("intraop image") >= 0);
      intraopSelector->setCurrentIndex(intraopSelector->findText("intraop image"));
      SliceView* axial = host.views()->sliceView(SliceOrientation::Axial);
      BS_CHECK(axial->background() == intraop && axial->overlay() == tmap);
      BS_CHECK(host.dataPanel()->overlaySelector()->currentNode() == tmap);
    }

    // A folder with the rigid module and a broken one.
    const auto folder = testing::temporaryFolder("HostModuleDiscoveryTest");
    BS_CHECK(QFile::copy(BRAINSHIFT_RIGID_MODULE_FILE, QString::fromStdString((folder / "libBrainShiftRigidRegistrationModule.so").string())));
    BS_CHECK(QFile::copy(BRAINSHIFT_THROWING_MODULE_FILE, QString::fromStdString((folder / "libThrowingTestModule.so").string())));
    std::ofstream(folder / "libBrokenModule.so") << "not a shared object\n";
    std::ofstream(folder / "README.txt") << "not a library: ignored\n";
    HostMainWindow host(QString::fromStdString(folder.string()));
    host.show();
    BS_CHECK(host.moduleTitles() == QStringList({"Data", "Rigid registration"}));
    BS_CHECK(host.moduleFailures().size() == 2);
    BS_CHECK(host.moduleFailures()[0].file.endsWith("libBrokenModule.so"));
    BS_CHECK(!host.moduleFailures()[0].reason.isEmpty());
    BS_CHECK(host.moduleFailures()[1].file.endsWith("libThrowingTestModule.so"));
    BS_CHECK(host.moduleFailures()[1].reason.contains("throws on purpose"));
    BS_CHECK_MSG(host.lastMessage().contains("2 modules could not be loaded") && host.lastMessage().contains("libBrokenModule.so"),
                 host.lastMessage().toStdString());
    BS_CHECK(host.selectModule("Rigid registration"));
    QWidget* panel = host.currentPanel();
    BS_CHECK(panel && panel->findChild<QWidget*>("intraopSelector"));
    BS_CHECK(!host.selectModule("No such module"));
    BS_CHECK(host.selectModule("Data") && host.currentPanel() == host.dataPanel());

    // No modules folder at all: reported, the host still has its own panel.
    HostMainWindow bare(QString::fromStdString((folder / "missing").string()));
    BS_CHECK(bare.moduleTitles() == QStringList({"Data"}));
    BS_CHECK(bare.moduleFailures().size() == 1 && bare.lastMessage().contains("does not exist"));
  });
}
