// The surface and simulation panel on the small built-in case (a 5 mm mesh, the truth's rigid
// transform and intraoperative labels): Cancel during the surface stage leaves the panel idle at
// once and nothing in the scene; a run puts the displacement-coloured brain surface under the
// rigid transform and the displacements on the mesh, with the bar at its end; an empty
// segmentation is the logic's error in the panel, the scene untouched; a finite element worker
// that dies mid-run is reported in the panel, the scene untouched, and the panel runs again.
#include "SurfaceAndSimulationPanel.h"
#include "SurfaceAndSimulationTestScene.h"
#include "BrainShiftTestingSupport.h"

#include <vtkDataArray.h>
#include <vtkPointData.h>

#include <QApplication>
#include <QProgressBar>
#include <QPushButton>
#include <QSignalSpy>
#include <QSpinBox>

#include <filesystem>
#include <fstream>
#include <iostream>

int SurfaceAndSimulationPanelTest(int argc, char* argv[])
{
  QApplication application(argc, argv);
  return brainshift::testing::runTest("SurfaceAndSimulationPanelTest", [] {
    using namespace brainshift;
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    const SimulatedCase c = simulateCase(parameters);
    Scene scene;
    const testing::SurfaceAndSimulationTestNodes nodes = testing::addSmallDeformationCase(scene, c);
    const auto& meshNode = nodes.mesh;
    const auto& intraopLabels = nodes.intraopLabels;
    const auto& rigid = nodes.rigid;
    SurfaceAndSimulationPanel panel(scene);
    // The ranks (and the surface's and the solve's parameters) are the configuration's.
    BS_CHECK(panel.ranksBox()->value() == Configuration{}.ranks);
    Configuration threeRanks;
    threeRanks.ranks = 3;
    BS_CHECK(SurfaceAndSimulationPanel(scene, threeRanks).ranksBox()->value() == 3);
    BS_CHECK(panel.intraopLabelsSelector()->setCurrentNodeId(QString::fromStdString(intraopLabels->id())));
    QSignalSpy finished(&panel, &SurfaceAndSimulationPanel::runFinished);
    QSignalSpy discarded(&panel, &SurfaceAndSimulationPanel::discardedRunFinished);
    QSignalSpy stages(&panel, &SurfaceAndSimulationPanel::stageStarted);
    const std::size_t nodesBefore = scene.nodes().size();

    // Cancelled while the surface is matched: idle at once; the solve never starts.
    panel.runButton()->click();
    BS_CHECK(panel.isRunning() && stages.count() == 1 && stages.first().at(0).toString() == "surface");
    BS_CHECK(panel.progressBar()->maximum() == 0); // no progress hook in the surface stage
    panel.cancelButton()->click();
    BS_CHECK(!panel.isRunning() && panel.runButton()->isEnabled());
    BS_CHECK(discarded.wait(120000));
    BS_CHECK(finished.isEmpty() && scene.nodes().size() == nodesBefore);
    BS_CHECK(!meshNode->mesh()->GetPointData()->GetArray("Displacement"));

    // A run.
    stages.clear();
    panel.run();
    BS_CHECK(finished.wait(180000));
    BS_CHECK_MSG(finished.last().at(0).toBool(), panel.statusText().toStdString());
    std::cout << panel.statusText().toStdString() << '\n';
    auto surface = scene.findByName<ModelNode>("brain surface");
    BS_CHECK(surface && surface->parentTransformId() == rigid->id());
    BS_CHECK(surface->display().scalarVisibility && surface->display().activeScalarName == "DisplacementMagnitude");
    vtkDataArray* magnitude = surface->mesh()->GetPointData()->GetArray("DisplacementMagnitude");
    BS_CHECK(magnitude);
    std::cout << "surface displacement up to " << magnitude->GetRange()[1] << " mm (truth: "
              << c.figures.maxBrainDisplacementMm << " mm)\n";
    BS_CHECK_MSG(magnitude->GetRange()[1] > 3.0 && magnitude->GetRange()[1] < 20.0, magnitude->GetRange()[1]);
    BS_CHECK(meshNode->mesh()->GetPointData()->GetArray("Displacement"));
    BS_CHECK(panel.progressBar()->value() == 100 && panel.statusText().contains("equations"));

    // An empty segmentation: the logic's message, nothing changed.
    auto empty = LabelImage::New();
    empty->CopyInformation(c.intraopLabels);
    empty->SetRegions(c.intraopLabels->GetLargestPossibleRegion());
    empty->Allocate();
    empty->FillBuffer(0);
    auto emptyNode = scene.add(LabelMapVolumeNode::create("empty labels", empty));
    BS_CHECK(panel.intraopLabelsSelector()->setCurrentNodeId(QString::fromStdString(emptyNode->id())));
    vtkPolyData* surfaceBefore = vtkPolyData::SafeDownCast(surface->mesh());
    panel.run();
    BS_CHECK(finished.wait(120000));
    BS_CHECK(!finished.last().at(0).toBool());
    std::cout << panel.statusText().toStdString() << '\n';
    BS_CHECK(panel.statusText().startsWith("Surface and simulation failed"));
    BS_CHECK(surface->mesh() == surfaceBefore && !panel.isRunning());

    // A worker that dies (killed, as by the kernel's out-of-memory killer): the panel says so,
    // the host goes on, the scene keeps the last result, and the real worker runs again.
    BS_CHECK(panel.intraopLabelsSelector()->setCurrentNodeId(QString::fromStdString(intraopLabels->id())));
    const std::filesystem::path dying = testing::temporaryFolder("SurfaceAndSimulationPanelTest") / "dying-worker.sh";
    {
      std::ofstream script(dying);
      script << "#!/bin/sh\necho 'preparing' >&2\nkill -9 $$\n";
    }
    std::filesystem::permissions(dying, std::filesystem::perms::owner_all);
    panel.setWorker(dying);
    panel.run();
    BS_CHECK(finished.wait(120000));
    BS_CHECK(!finished.last().at(0).toBool());
    std::cout << panel.statusText().toStdString() << '\n';
    BS_CHECK(panel.statusText().startsWith("Surface and simulation failed") && panel.statusText().contains("worker"));
    BS_CHECK(surface->mesh() == surfaceBefore && !panel.isRunning() && panel.runButton()->isEnabled());
    panel.setWorker({});
    panel.run();
    BS_CHECK(finished.wait(120000));
    BS_CHECK_MSG(finished.last().at(0).toBool(), panel.statusText().toStdString());
    BS_CHECK(surface->mesh() != surfaceBefore);
  });
}
