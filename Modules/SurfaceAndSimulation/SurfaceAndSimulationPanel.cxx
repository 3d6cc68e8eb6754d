#include "SurfaceAndSimulationPanel.h"

#include "ActiveSurfaceLogic.h"
#include "BiomechanicalModel.h"
#include "FiniteElementSolver.h"
#include "ImageMatchConstraints.h"

#include <vtkPointData.h>

#include <QCheckBox>
#include <QElapsedTimer>
#include <QFormLayout>
#include <QSpinBox>
#include <QTimer>
#include <QVBoxLayout>

#include <functional>
#include <optional>

namespace brainshift {

SurfaceAndSimulationPanel::SurfaceAndSimulationPanel(Scene& scene, const Configuration& configuration, QWidget* parent)
  : QWidget(parent)
  , scene_(scene)
  , configuration_(configuration)
{
  mesh_ = new NodeSelector({NodeKind::Model}, {}, this);
  preopLabels_ = new NodeSelector({NodeKind::LabelMapVolume}, {}, this);
  intraopLabels_ = new NodeSelector({NodeKind::LabelMapVolume}, {}, this);
  intraop_ = new NodeSelector({NodeKind::ScalarVolume}, {}, this);
  transform_ = new NodeSelector({NodeKind::Transform}, {}, this);
  preop_ = new NodeSelector({NodeKind::ScalarVolume}, "preop", this); // the preoperative MRI, not an overlay
  blockMatching_ = new QCheckBox(tr("Block matching inside the brain"), this);
  blockMatching_->setChecked(configuration_.blockMatching.enabled); // as the command line
  blockMatching_->setToolTip(tr("Blocks of the preoperative volume found again in the intraoperative one, "
                                "as soft constraints of a second solve"));
  ranks_ = new QSpinBox(this);
  ranks_->setRange(1, 64);
  ranks_->setValue(configuration_.ranks); // as the command line
  ranks_->setToolTip(tr("MPI ranks of the finite element solve"));
  controls_ = new StageRunControls(tr("Surface and simulation"), this);
  boardReader_ = new QTimer(this);
  boardReader_->setInterval(50);
  connect(boardReader_, &QTimer::timeout, this, &SurfaceAndSimulationPanel::readProgressBoard);

  auto* form = new QFormLayout;
  form->addRow(tr("Mesh"), mesh_);
  form->addRow(tr("Preoperative labels"), preopLabels_);
  form->addRow(tr("Intraoperative labels"), intraopLabels_);
  form->addRow(tr("Intraoperative volume"), intraop_);
  form->addRow(tr("Rigid intraop_to_preop"), transform_);
  form->addRow(tr("Preoperative volume"), preop_);
  form->addRow(QString(), blockMatching_);
  form->addRow(tr("Ranks"), ranks_);
  auto* column = new QVBoxLayout(this);
  column->addLayout(form);
  column->addWidget(controls_);
  column->addStretch(1);

  for (NodeSelector* selector : {mesh_, preopLabels_, intraopLabels_, intraop_, transform_, preop_}) selector->setScene(&scene_);
  connect(controls_, &StageRunControls::runRequested, this, &SurfaceAndSimulationPanel::run);
  connect(controls_, &StageRunControls::runningChanged, this, &SurfaceAndSimulationPanel::lockInputs);
  connect(controls_, &StageRunControls::finished, this, &SurfaceAndSimulationPanel::runFinished);
  connect(controls_, &StageRunControls::discarded, this, &SurfaceAndSimulationPanel::discardedRunFinished);
}

SurfaceAndSimulationPanel::~SurfaceAndSimulationPanel()
{
  // The controls go with this panel and cancel its run: no worker ranks outlive the panel's interest.
  for (NodeSelector* selector : {mesh_, preopLabels_, intraopLabels_, intraop_, transform_, preop_}) selector->setScene(nullptr);
}

void SurfaceAndSimulationPanel::lockInputs(bool locked)
{
  for (QWidget* input : std::initializer_list<QWidget*>{mesh_, preopLabels_, intraopLabels_, intraop_, transform_, preop_, blockMatching_, ranks_}) {
    input->setEnabled(!locked);
  }
  if (locked) boardReader_->start();
  else boardReader_->stop();
}

void SurfaceAndSimulationPanel::readProgressBoard()
{
  if (!board_) return;
  std::string stage;
  double fraction = 0;
  {
    std::lock_guard<std::mutex> lock(board_->mutex);
    stage = board_->stage;
    fraction = board_->fraction;
  }
  if (!stage.empty()) showStage(QString::fromStdString(stage), fraction);
}

void SurfaceAndSimulationPanel::showStage(const QString& stage, double fraction)
{
  if (!isRunning()) return; // a late report of a cancelled run
  // The surface stage and the block matching report no fraction: the bar stays. The solves'
  // stages share the bar.
  if (stage != "surface" && stage != "block matching") {
    static const QStringList solverStages{"partition", "assembly", "setup", "solve", "done"};
    const int index = std::max(0, int(solverStages.indexOf(stage)));
    controls_->showFraction((index + std::clamp(fraction, 0.0, 1.0)) / (solverStages.size() - 1));
  }
  if (stage != lastStage_) {
    lastStage_ = stage;
    controls_->setStatus(stage == "surface"          ? tr("Matching the brain surface ...")
                         : stage == "block matching" ? tr("Matching blocks inside the brain ...")
                                                     : tr("Finite element solve: %1 ...").arg(stage));
    emit stageStarted(stage);
  }
}

namespace {
/// The worker's own copies and references (BackgroundRun.h): the mesh is copied, since the
/// displacements are attached to it; images and the transform are only read.
struct DeformationInputs {
  vtkSmartPointer<vtkUnstructuredGrid> mesh;
  LabelImage::ConstPointer preop, intraopSegmentation;
  ScalarImage::ConstPointer image;
  ScalarImage::ConstPointer preopImage; ///< null: no block matching
  bool matchingWanted = false;          ///< block matching was asked for (with or without the volume)
  SpatialTransform::ConstPointer rigid;
  std::string meshId, rigidId;
  int ranks = 1;
  std::filesystem::path worker;
  Configuration configuration; ///< the surface's and the solve's parameters
};

using StageReport = std::function<void(const std::string&, double)>;

/// What the run delivers to the scene and the status line.
struct DeformationOutcome {
  vtkSmartPointer<vtkPolyData> brainSurface;
  std::size_t imposed = 0;
  double maximum = 0, residual = 0;
  FiniteElementResult solved;
  std::optional<ImageDrivenSolve> matched; ///< with block matching
  bool matchingWithoutVolume = false;      ///< asked for, but no preoperative volume was chosen
  double seconds = 0;
};

/// The block matches from the surface-driven solve, and the mesh solved again with them, both
/// solves on one worker with the options for repeated solves (as the command line's `simulate`).
FiniteElementResult solveWithBlockMatches(const DeformationInputs& in, FiniteElementJob job, const FiniteElementRunOptions& options,
                                          bool tumourResected, const StageReport& report, DeformationOutcome& outcome)
{
  job.solverOptions = solverOptionsForRepeatedSolves(job.solverOptions);
  FiniteElementSession session(job, options);
  const FiniteElementResult surfaceOnly = session.solve(job.fixedDisplacements);
  throwIfCancelled(options.cancel, "surface and simulation");
  report("block matching", 0.0);
  ImageDrivenSolveInputs inputs;
  inputs.preopImage = in.preopImage.GetPointer();
  inputs.preopLabels = in.preop.GetPointer();
  inputs.intraopImage = in.image.GetPointer();
  inputs.intraopLabels = in.intraopSegmentation.GetPointer();
  inputs.rigidIntraopToPreop = in.rigid.GetPointer();
  inputs.tumourResected = tumourResected;
  outcome.matched = solveWithImageMatches(in.mesh, job, surfaceOnly, inputs, in.configuration, [&session](const FiniteElementJob& constrained) {
    return session.solve(constrained.fixedNodes, constrained.fixedDisplacements, constrained.softConstraints, constrained.rejection);
  });
  return outcome.matched->result;
}

/// On the worker thread: the active surface, then the finite element solve; the displacements
/// are attached to the copied mesh.
DeformationOutcome deformAndSolve(const DeformationInputs& in, CancelFlag cancel, const StageReport& report)
{
  QElapsedTimer clock;
  clock.start();
  report("surface", 0.0);
  ActiveSurfaceParameters surfaceParameters = activeSurfaceParametersFrom(in.configuration);
  surfaceParameters.cancel = cancel;
  const ActiveSurfaceResult surface =
    deformBrainSurface(in.mesh, in.preop.GetPointer(), *in.intraopSegmentation, in.image.GetPointer(), *in.rigid, surfaceParameters);
  throwIfCancelled(cancel, "surface and simulation");
  const FiniteElementJob job = finiteElementJobFromModel(in.mesh, surface.surface, in.configuration, "the mesh", "the brain surface");
  FiniteElementRunOptions options;
  options.ranks = in.ranks;
  options.worker = in.worker;
  options.cancel = cancel;
  options.progress = report;
  DeformationOutcome outcome;
  outcome.solved = in.preopImage ? solveWithBlockMatches(in, job, options, surface.tumourResected, report, outcome)
                                 : solveWithWorker(job, options);
  attachDisplacements(in.mesh, outcome.solved);
  outcome.matchingWithoutVolume = in.matchingWanted && !in.preopImage;
  outcome.seconds = clock.elapsed() / 1000.0;
  outcome.brainSurface = surface.surface;
  outcome.imposed = surface.imposedNodes;
  outcome.maximum = surface.maxDisplacementMm;
  outcome.residual = surface.meanResidualMm;
  return outcome;
}

/// The deformed brain surface into the scene: the node of that name takes it, else a new node
/// coloured by the displacement, under the rigid transform when the scene still holds it.
void placeBrainSurface(Scene& scene, const std::string& name, const vtkSmartPointer<vtkPolyData>& brainSurface, const std::string& rigidId)
{
  auto surfaceNode = scene.findByName<ModelNode>(name);
  if (surfaceNode) {
    surfaceNode->setMesh(brainSurface);
    return;
  }
  surfaceNode = ModelNode::create(name, brainSurface);
  ModelDisplay display;
  display.scalarVisibility = true;
  display.activeScalarName = "DisplacementMagnitude";
  surfaceNode->setDisplay(display);
  surfaceNode->setRole("preop");
  if (scene.node(rigidId)) surfaceNode->setParentTransformId(rigidId);
  scene.add(surfaceNode);
}

QString doneMessage(const DeformationOutcome& o)
{
  QString matches;
  if (o.matched && o.matched->used) {
    matches = SurfaceAndSimulationPanel::tr(" %1 of %2 block matches kept, misfit %3 -> %4 mm;")
                .arg(keptSoftConstraints(o.solved))
                .arg(o.matched->matching.matches.size())
                .arg(o.matched->rmsMisfitSurfaceOnlyMm, 0, 'f', 2)
                .arg(o.solved.rmsMisfitPerRoundMm.empty() ? 0.0 : o.solved.rmsMisfitPerRoundMm.back(), 0, 'f', 2);
  } else if (o.matched) {
    matches = SurfaceAndSimulationPanel::tr(" no block matched (%1 selected): the surface's solve;").arg(o.matched->matching.selected);
  } else if (o.matchingWithoutVolume) {
    matches = SurfaceAndSimulationPanel::tr(" no block matching (choose the preoperative volume): the surface's solve;");
  }
  return SurfaceAndSimulationPanel::tr("Done in %1 s: %2 surface nodes imposed (up to %3 mm, residual %4 mm);%5 %6 equations on %7 "
                                   "rank(s), %8 iterations, residual %9.")
    .arg(o.seconds, 0, 'f', 1)
    .arg(o.imposed)
    .arg(o.maximum, 0, 'f', 1)
    .arg(o.residual, 0, 'f', 2)
    .arg(matches)
    .arg(o.solved.equations)
    .arg(o.solved.ranks)
    .arg(o.solved.iterations)
    .arg(o.solved.relativeResidual, 0, 'e', 1);
}
} // namespace

void SurfaceAndSimulationPanel::run()
{
  if (isRunning()) return;
  auto meshNode = std::dynamic_pointer_cast<ModelNode>(mesh_->currentNode());
  auto preopLabels = std::dynamic_pointer_cast<LabelMapVolumeNode>(preopLabels_->currentNode());
  auto intraopLabels = std::dynamic_pointer_cast<LabelMapVolumeNode>(intraopLabels_->currentNode());
  auto intraop = std::dynamic_pointer_cast<ScalarVolumeNode>(intraop_->currentNode());
  auto transform = std::dynamic_pointer_cast<TransformNode>(transform_->currentNode());
  auto preop = std::dynamic_pointer_cast<ScalarVolumeNode>(preop_->currentNode());
  auto* meshData = meshNode ? vtkUnstructuredGrid::SafeDownCast(meshNode->mesh()) : nullptr;
  if (!meshData || !preopLabels || !preopLabels->image() || !intraopLabels || !intraopLabels->image() || !intraop ||
      !intraop->image() || !transform || !transform->transformFromParent()) {
    controls_->setStatus(tr("Choose a tetrahedral mesh, both label maps, the intraoperative volume and the rigid transform first."));
    return;
  }
  DeformationInputs inputs;
  inputs.mesh = vtkSmartPointer<vtkUnstructuredGrid>::New();
  inputs.mesh->DeepCopy(meshData);
  inputs.preop = preopLabels->image();
  inputs.intraopSegmentation = intraopLabels->image();
  inputs.image = intraop->image();
  // As the command line: block matching needs the preoperative volume; without one the solve is
  // the surface's alone, and the status says so.
  inputs.matchingWanted = blockMatching_->isChecked();
  if (inputs.matchingWanted && preop) inputs.preopImage = preop->image();
  inputs.rigid = transform->transformFromParent();
  inputs.meshId = meshNode->id();
  inputs.rigidId = transform->id();
  inputs.ranks = ranks_->value();
  inputs.configuration = configuration_;
  inputs.worker = worker_.empty() ? workerBesideExecutable() : worker_;
  auto board = std::make_shared<ProgressBoard>();
  board_ = board;
  const StageReport report = [board](const std::string& stage, double fraction) {
    std::lock_guard<std::mutex> lock(board->mutex);
    board->stage = stage;
    board->fraction = fraction;
  };
  lastStage_.clear();
  controls_->start(tr("Matching the brain surface ..."), [this, inputs, report](CancelFlag cancel) -> BackgroundRun::Delivery {
    const DeformationOutcome outcome = deformAndSolve(inputs, cancel, report);
    return [this, mesh = inputs.mesh, meshId = inputs.meshId, rigidId = inputs.rigidId, outcome] {
      if (auto meshNode = std::dynamic_pointer_cast<ModelNode>(scene_.node(meshId))) meshNode->setMesh(mesh);
      placeBrainSurface(scene_, surfaceNodeName().toStdString(), outcome.brainSurface, rigidId);
      controls_->finish(true, doneMessage(outcome));
    };
  });
  showStage("surface", 0.0);
}

} // namespace brainshift
