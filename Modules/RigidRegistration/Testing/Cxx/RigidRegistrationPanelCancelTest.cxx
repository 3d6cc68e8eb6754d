// Cancel: the panel is idle at once, the registration stops at its next iteration (on the run's
// cancel flag) instead of running to its end, nothing reaches the scene, and the panel can run
// again right away.
#include "BrainShiftTestingSupport.h"
#include "RigidRegistrationPanel.h"
#include "RigidRegistrationPanelTestSupport.h"

#include <QApplication>
#include <QElapsedTimer>
#include <QPushButton>
#include <QSignalSpy>

int RigidRegistrationPanelCancelTest(int argc, char* argv[])
{
  QApplication application(argc, argv);
  return brainshift::testing::runTest("RigidRegistrationPanelCancelTest", [] {
    using namespace brainshift;
    Scene scene;
    testing::addSmallCase(scene);
    RigidRegistrationPanel panel(scene);
    panel.setParameters(testing::quickRigidParameters());
    QSignalSpy finished(&panel, &RigidRegistrationPanel::runFinished);
    QSignalSpy discarded(&panel, &RigidRegistrationPanel::discardedRunFinished);

    panel.run();
    BS_CHECK(panel.isRunning());
    QElapsedTimer clock;
    clock.start();
    panel.cancelButton()->click();
    BS_CHECK_MSG(clock.elapsed() < 100, clock.elapsed() << " ms to cancel");
    BS_CHECK(!panel.isRunning() && panel.runButton()->isEnabled() && !panel.cancelButton()->isEnabled());
    BS_CHECK(panel.statusText().startsWith("Cancelled"));

    BS_CHECK(discarded.wait(120000));
    BS_CHECK_MSG(discarded.first().at(0).toBool(), "the cancelled registration ran to its end");
    BS_CHECK(finished.isEmpty());
    BS_CHECK(scene.nodesOfType<TransformNode>().empty());

    // A run after a cancel completes normally.
    panel.run();
    BS_CHECK(finished.wait(120000));
    BS_CHECK_MSG(finished.first().at(0).toBool(), panel.statusText().toStdString());
    BS_CHECK(scene.nodesOfType<TransformNode>().size() == 1);
    BS_CHECK(discarded.count() == 1);
  });
}
