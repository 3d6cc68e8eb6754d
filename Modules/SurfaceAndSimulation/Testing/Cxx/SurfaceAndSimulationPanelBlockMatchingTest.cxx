// The surface and simulation panel with block matching (on by default, as the command line's
// `simulate`), on the small built-in case: with the preoperative volume chosen (the selector offers
// the preoperative MRI, not the scan), the blocks are matched between the two solves ("block
// matching" among the stages), the status says how many matches were kept and how their misfit
// fell, and the displacements differ from the surface's solve alone (the box unchecked). Checked
// without a preoperative volume, the solve is the surface's and the status says why.
#include "SurfaceAndSimulationPanel.h"
#include "SurfaceAndSimulationTestScene.h"
#include "BrainShiftTestingSupport.h"

#include <vtkDataArray.h>
#include <vtkPointData.h>

#include <QApplication>
#include <QCheckBox>
#include <QSignalSpy>

#include <cmath>
#include <iostream>
#include <vector>

namespace {
using namespace brainshift;

/// The mesh node's Displacement, node by node (empty when none is attached).
std::vector<double> displacementsOf(const ModelNode& mesh)
{
  std::vector<double> values;
  vtkDataArray* u = mesh.mesh()->GetPointData()->GetArray("Displacement");
  for (vtkIdType i = 0; u && i < u->GetNumberOfTuples(); ++i) {
    for (int c = 0; c < 3; ++c) values.push_back(u->GetComponent(i, c));
  }
  return values;
}

/// Runs the panel once and returns whether it succeeded (its status printed).
bool runOnce(SurfaceAndSimulationPanel& panel, QSignalSpy& finished)
{
  panel.run();
  const bool ended = finished.wait(180000);
  std::cout << panel.statusText().toStdString() << '\n';
  return ended && finished.last().at(0).toBool();
}
} // namespace

int SurfaceAndSimulationPanelBlockMatchingTest(int argc, char* argv[])
{
  QApplication application(argc, argv);
  return brainshift::testing::runTest("SurfaceAndSimulationPanelBlockMatchingTest", [] {
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    const SimulatedCase c = simulateCase(parameters);
    Scene scene;
    const testing::SurfaceAndSimulationTestNodes nodes = testing::addSmallDeformationCase(scene, c);
    nodes.intraopImage->setRole("intraop");
    auto preopImage = scene.add(ScalarVolumeNode::create("preop image", c.preopImage));
    preopImage->setRole("preop");
    const auto& meshNode = nodes.mesh;
    const auto& intraopLabels = nodes.intraopLabels;

    Configuration withoutMatching;
    withoutMatching.blockMatching.enabled = false;
    BS_CHECK(!SurfaceAndSimulationPanel(scene, withoutMatching).blockMatchingBox()->isChecked());
    SurfaceAndSimulationPanel panel(scene);
    BS_CHECK(panel.blockMatchingBox()->isChecked());
    BS_CHECK(panel.preopSelector()->currentNodeId().toStdString() == preopImage->id());
    BS_CHECK(panel.intraopLabelsSelector()->setCurrentNodeId(QString::fromStdString(intraopLabels->id())));
    QSignalSpy finished(&panel, &SurfaceAndSimulationPanel::runFinished);
    QSignalSpy stages(&panel, &SurfaceAndSimulationPanel::stageStarted);

    BS_CHECK(runOnce(panel, finished));
    QStringList seen;
    for (const QList<QVariant>& stage : stages) seen << stage.at(0).toString();
    BS_CHECK_MSG(seen.contains("block matching"), seen.join(", ").toStdString());
    BS_CHECK(panel.statusText().contains("block matches kept"));
    const std::vector<double> withMatches = displacementsOf(*meshNode);

    panel.blockMatchingBox()->setChecked(false);
    BS_CHECK(runOnce(panel, finished));
    BS_CHECK(!panel.statusText().contains("block"));
    const std::vector<double> surfaceAlone = displacementsOf(*meshNode);
    BS_CHECK(withMatches.size() == surfaceAlone.size() && !withMatches.empty());
    double largestDifference = 0;
    for (std::size_t i = 0; i < withMatches.size() && i < surfaceAlone.size(); ++i) {
      largestDifference = std::max(largestDifference, std::abs(withMatches[i] - surfaceAlone[i]));
    }
    std::cout << "the block matches moved a node by up to " << largestDifference << " mm\n";
    BS_CHECK_MSG(largestDifference > 0.1, largestDifference);

    // Asked for without the preoperative volume: the surface's solve, and the status says why.
    panel.blockMatchingBox()->setChecked(true);
    scene.remove(preopImage->id());
    BS_CHECK(panel.preopSelector()->currentNodeId().isEmpty());
    BS_CHECK(runOnce(panel, finished));
    BS_CHECK(panel.statusText().contains("no block matching (choose the preoperative volume)"));
  });
}
