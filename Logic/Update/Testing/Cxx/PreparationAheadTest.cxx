// A first scan's mesh and preoperative brain boundary made beside its first stages
// (PreparationAhead), on the small built-in case:
// - the boundary made ahead gives the surface stage exactly what it finds in line: the same
//   displacement at every node, to the last bit;
// - the whole pipeline takes both (the report says so), the mesh the mesh stage's own (its nodes
//   and tetrahedra);
// - a cancel reaches the thread: asked for the boundary with the run's Cancel set, it stops with
//   CancelledError instead of finishing;
// - a run cancelled as its classification starts stops there, the thread abandoned and joined;
// - not started where the run would not make them: a previous scan given, a watch session, no
//   labels.
#include "ActiveSurfaceLogic.h"
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "Configuration.h"
#include "LabelMapMesher.h"
#include "PreparationAhead.h"
#include "UpdatePipeline.h"
#include "VolumeIO.h"

#include <itkEuler3DTransform.h>
#include <vtkDataArray.h>
#include <vtkPointData.h>

#include <atomic>
#include <cmath>

namespace {
namespace fs = std::filesystem;
using namespace brainshift;

double largestDifference(vtkDataArray* a, vtkDataArray* b)
{
  BS_CHECK(a && b && a->GetNumberOfTuples() == b->GetNumberOfTuples() && a->GetNumberOfComponents() == b->GetNumberOfComponents());
  double largest = 0;
  for (vtkIdType i = 0; i < a->GetNumberOfTuples(); ++i) {
    for (int c = 0; c < a->GetNumberOfComponents(); ++c) largest = std::max(largest, std::fabs(a->GetComponent(i, c) - b->GetComponent(i, c)));
  }
  return largest;
}

/// The boundary made ahead against the surface stage's own fit, on the scan's true labels; the
/// mesh it was made on.
LabelMapMesh checkBoundaryMadeAheadIsTheSurfaceStages(const CaseFiles& files, const Configuration& configuration)
{
  const LabelImage::Pointer preopLabels = readLabelVolume(files.preopLabels);
  const LabelImage::Pointer intraopLabels = readLabelVolume(files.truthIntraopLabels);
  const ScalarImage::Pointer intraopImage = readScalarVolume(files.intraopImage);
  LabelMapMesh mesh = meshLabelMap(*preopLabels, meshingParametersFrom(configuration));
  const ActiveSurfaceParameters surfaceParameters = activeSurfaceParametersFrom(configuration);
  const PreoperativeBrainBoundary ahead = preoperativeBrainBoundary(mesh.mesh, *preopLabels, surfaceParameters);
  BS_CHECK(ahead.surface && ahead.surface->GetPointData()->GetArray("PreopBoundary") && ahead.seconds > 0);
  BS_CHECK_MSG(ahead.surface->GetPointData()->GetArray("DisplacementMagnitude")->GetRange()[1] == 0, "the boundary made ahead moves a node");
  const auto identity = itk::Euler3DTransform<double>::New();
  const ActiveSurfaceResult inLine = deformBrainSurface(mesh.mesh, preopLabels, *intraopLabels, intraopImage, *identity, surfaceParameters);
  const ActiveSurfaceResult fromAhead =
    deformBrainSurface(mesh.mesh, preopLabels, *intraopLabels, intraopImage, *identity, surfaceParameters, {}, ahead.surface);
  const double difference = largestDifference(inLine.surface->GetPointData()->GetArray("Displacement"),
                                              fromAhead.surface->GetPointData()->GetArray("Displacement"));
  std::printf("surface displacement, in line against the boundary made ahead: largest difference %.3g mm; up to %.2f mm\n", difference,
              inLine.maxDisplacementMm);
  BS_CHECK_MSG(difference == 0, difference);
  BS_CHECK(inLine.maxDisplacementMm > 1 && inLine.imposedNodes == fromAhead.imposedNodes);
  return mesh;
}

/// The whole pipeline takes both: the mesh stage's the mesh made in line (`mesh`).
void checkPipelineTakesThem(RunOptions options, const fs::path& folder, const LabelMapMesh& mesh)
{
  options.outputDir = folder;
  fs::create_directories(options.outputDir);
  RunReport report(options.outputDir / "report.json");
  RunContext context(options, configurationFor(options), report);
  context.setProgressCallback([](const UpdateProgress&) {});
  runRegistration(context);
  BS_CHECK(!context.preparationAhead()); // released when the pipeline ended
  const nlohmann::json& document = report.document();
  BS_CHECK_MSG(document["stages"]["mesh"]["made_ahead_seconds"].is_number(), document["stages"]["mesh"].dump());
  BS_CHECK(document["stages"]["mesh"]["nodes"] == mesh.quality.nodes && document["stages"]["mesh"]["tetrahedra"] == mesh.quality.tetrahedra);
  BS_CHECK(document["stages"]["surface"]["preop_boundary_from"] == "made beside the rigid registration");
}

/// A run cancelled as the classification starts (the preparation then still at work beside it);
/// and a cancel asked at once reaches the thread (the mesher and the boundary's fit check it).
void checkCancel(RunOptions options, const fs::path& root)
{
  options.outputDir = root / "cancelled";
  fs::create_directories(options.outputDir);
  {
    std::atomic<bool> cancel{false};
    RunReport report(options.outputDir / "report.json");
    RunContext context(options, configurationFor(options), report);
    context.setCancelFlag(&cancel);
    bool aheadWhenCancelled = false;
    context.setProgressCallback([&](const UpdateProgress& step) {
      if (step.stage == "classify" && step.message.empty()) {
        aheadWhenCancelled = context.preparationAhead() != nullptr;
        cancel = true;
      }
    });
    BS_CHECK_THROWS(runRegistration(context), CancelledError, "");
    BS_CHECK(aheadWhenCancelled);
    BS_CHECK(!context.preparationAhead());
    const nlohmann::json& document = report.document();
    BS_CHECK(!document.contains("stages") || !document["stages"].contains("mesh"));
  }
  options.outputDir = root / "abandoned";
  RunReport report(options.outputDir / "report.json");
  RunContext context(options, configurationFor(options), report);
  const std::shared_ptr<PreparationAhead> ahead = PreparationAhead::startFor(context);
  BS_CHECK(ahead != nullptr);
  std::atomic<bool> cancelled{true};
  BS_CHECK_THROWS(ahead->boundary(&cancelled), CancelledError, "");
}

/// Not started where the run would not make them: a previous scan given, a watch session (it
/// prepared them before surgery), no labels.
void checkNotStarted(const RunOptions& options, const fs::path& root, const fs::path& previous)
{
  RunOptions later = options;
  later.outputDir = root / "later";
  later.previous = previous;
  RunReport report(later.outputDir / "report.json");
  RunContext context(later, configurationFor(later), report);
  BS_CHECK(!PreparationAhead::startFor(context));
  RunContext inSession(options, configurationFor(options), report);
  SerialScanSession session;
  inSession.joinSession(session);
  BS_CHECK(!PreparationAhead::startFor(inSession));
  RunOptions unlabelled = options;
  unlabelled.preopLabels.clear();
  RunContext withoutLabels(unlabelled, configurationFor(unlabelled), report);
  BS_CHECK(!PreparationAhead::startFor(withoutLabels));
}
} // namespace

int PreparationAheadTest(int, char*[])
{
  return brainshift::testing::runTest("PreparationAheadTest", [] {
    const fs::path root = brainshift::testing::temporaryFolder("PreparationAheadTest");
    CaseParameters parameters;
    parameters.size = CaseSize::Small;
    writeCase(simulateCase(parameters), parameters, root / "case");
    const CaseFiles files(root / "case");
    const LabelMapMesh mesh = checkBoundaryMadeAheadIsTheSurfaceStages(files, Configuration{});
    RunOptions options;
    options.preopImage = files.preopImage;
    options.preopLabels = files.preopLabels;
    options.intraopImage = files.intraopImage;
    checkPipelineTakesThem(options, root / "register", mesh);
    checkCancel(options, root);
    checkNotStarted(options, root, root / "register");
  });
}
