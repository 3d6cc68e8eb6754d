// The evaluation panel: known errors (0, 1 and 2 mm) of a rigid transform against three pairs
// appear in the table and the summary; a click on a row asks the host to show that pair's
// intraoperative point; without landmarks it says what is missing.
#include "BrainShiftTestingSupport.h"
#include "EvaluationPanel.h"
#include "SyntheticData.h"

#include <QApplication>
#include <QPushButton>
#include <QTableWidget>

int EvaluationPanelTest(int argc, char* argv[])
{
  QApplication application(argc, argv);
  return brainshift::testing::runTest("EvaluationPanelTest", [] {
    using namespace brainshift;
    using testing::point;
    Scene scene;
    auto rigid = testing::makeRigidTransform();
    scene.add(TransformNode::create("rigid intraop_to_preop", rigid.GetPointer()));

    ModuleContext context;
    std::vector<std::array<double, 3>> shown;
    context.showPoint = [&shown](const std::array<double, 3>& p) { shown.push_back(p); };
    EvaluationPanel panel(scene, context);
    BS_CHECK(!panel.evaluate());
    BS_CHECK(panel.summaryText().contains("Choose"));

    // Preoperative points the transform misses by 0, 1 and 2 mm along L.
    std::vector<LandmarkPair> pairs;
    const PhysicalPoint intraop[3] = {point(0, 0, 0), point(10, -20, 30), point(-15, 5, 12)};
    for (int i = 0; i < 3; ++i) {
      PhysicalPoint preop = rigid->TransformPoint(intraop[i]);
      preop[0] += i;
      pairs.push_back({"brain-0" + std::to_string(i + 1), preop, intraop[i]});
    }
    scene.add(LandmarksNode::create("truth landmarks", pairs));
    BS_CHECK(panel.landmarksSelector()->count() == 1);
    panel.evaluateButton()->click();
    QTableWidget& table = *panel.table();
    BS_CHECK(table.rowCount() == 3);
    for (int row = 0; row < 3; ++row) {
      BS_CHECK(table.item(row, 0)->text() == QString("brain-0%1").arg(row + 1));
      BS_CHECK_NEAR(table.item(row, 1)->data(Qt::UserRole).toDouble(), double(row), 1e-9);
    }
    BS_CHECK_MSG(panel.summaryText().contains("3 pairs: mean 1.00 mm") && panel.summaryText().contains("max 2.00 mm"),
                 panel.summaryText().toStdString());

    emit table.cellClicked(2, 0);
    BS_CHECK(shown.size() == 1);
    BS_CHECK(shown[0] == (std::array<double, 3>{-15, 5, 12}));
  });
}
