#include "RigidRegistrationPanel.h"

#include <QCheckBox>
#include <QElapsedTimer>
#include <QFormLayout>
#include <QVBoxLayout>

#include <initializer_list>

namespace brainshift {

RigidRegistrationPanel::RigidRegistrationPanel(Scene& scene, const Configuration& configuration, QWidget* parent)
  : QWidget(parent)
  , scene_(scene)
  , parameters_(rigidRegistrationParametersFrom(configuration))
{
  intraop_ = new NodeSelector({NodeKind::ScalarVolume}, {}, this);
  intraop_->setObjectName("intraopSelector");
  preop_ = new NodeSelector({NodeKind::ScalarVolume}, {}, this);
  preop_->setObjectName("preopSelector");
  preopLabels_ = new NodeSelector({NodeKind::LabelMapVolume}, {}, this);
  preopLabels_->setObjectName("preopLabelsSelector");
  useLabels_ = new QCheckBox(tr("Mask the metric with the labels"), this);
  controls_ = new StageRunControls(tr("Rigid registration"), this);
  connect(controls_, &StageRunControls::runRequested, this, &RigidRegistrationPanel::run);
  connect(controls_, &StageRunControls::runningChanged, this, &RigidRegistrationPanel::lockInputs);
  connect(controls_, &StageRunControls::finished, this, &RigidRegistrationPanel::runFinished);
  connect(controls_, &StageRunControls::discarded, this, &RigidRegistrationPanel::discardedRunFinished);

  auto* form = new QFormLayout;
  form->addRow(tr("Intraoperative (fixed)"), intraop_);
  form->addRow(tr("Preoperative (moving)"), preop_);
  form->addRow(tr("Preoperative labels"), preopLabels_);
  form->addRow(useLabels_);
  auto* column = new QVBoxLayout(this);
  column->addLayout(form);
  column->addWidget(controls_);
  column->addStretch(1);

  intraop_->setScene(&scene_);
  preop_->setScene(&scene_);
  preopLabels_->setScene(&scene_);
  // The usual case: volumes with the intraoperative and preoperative roles pick themselves, now
  // and when a scene is loaded later (the selectors follow the scene before this observer runs).
  for (const auto& node : scene_.nodes()) chooseByRole(*node);
  sceneObserver_ = scene_.addObserver([this](const SceneEvent& event) {
    if (event.type == SceneEventType::NodeAdded || event.type == SceneEventType::NodeModified) chooseByRole(*event.node);
  });
  useLabels_->setChecked(preopLabels_->count() > 0);
}

RigidRegistrationPanel::~RigidRegistrationPanel()
{
  scene_.removeObserver(sceneObserver_);
  intraop_->setScene(nullptr);
  preop_->setScene(nullptr);
  preopLabels_->setScene(nullptr);
}

void RigidRegistrationPanel::chooseByRole(const Node& node)
{
  if (isRunning()) return;
  const QString id = QString::fromStdString(node.id());
  // A selector whose choice does not have the role takes the first node that has it.
  auto offer = [&id](NodeSelector* selector, const std::string& role, const Node& candidate) {
    const auto current = selector->currentNode();
    return candidate.role() == role && (!current || current.get() == &candidate || current->role() != role) &&
           selector->setCurrentNodeId(id);
  };
  if (node.kind() == NodeKind::ScalarVolume) {
    offer(intraop_, "intraop", node);
    offer(preop_, "preop", node);
  } else if (node.kind() == NodeKind::LabelMapVolume) {
    if (offer(preopLabels_, "preop", node)) useLabels_->setChecked(true);
  }
}

void RigidRegistrationPanel::lockInputs(bool locked)
{
  for (QWidget* input : std::initializer_list<QWidget*>{intraop_, preop_, preopLabels_, useLabels_}) input->setEnabled(!locked);
}

void RigidRegistrationPanel::run()
{
  if (isRunning()) return;
  auto intraop = std::dynamic_pointer_cast<ScalarVolumeNode>(intraop_->currentNode());
  auto preop = std::dynamic_pointer_cast<ScalarVolumeNode>(preop_->currentNode());
  if (!intraop || !preop || !intraop->image() || !preop->image()) {
    controls_->setStatus(tr("Choose an intraoperative and a preoperative volume first."));
    return;
  }
  if (intraop == preop) {
    controls_->setStatus(tr("The intraoperative and the preoperative volume are the same node."));
    return;
  }
  auto labels = useLabels_->isChecked() ? std::dynamic_pointer_cast<LabelMapVolumeNode>(preopLabels_->currentNode()) : nullptr;

  // The worker holds its own references to the images: the scene may change meanwhile (nodes
  // replace images rather than edit them in place), and nothing of the scene is touched off
  // the GUI thread.
  ScalarImage::ConstPointer fixedImage = intraop->image(), movingImage = preop->image();
  LabelImage::ConstPointer movingLabels = labels ? labels->image() : nullptr;
  const RigidRegistrationParameters chosen = parameters_;
  const QString message =
    tr("Registering %1 to %2 ...").arg(QString::fromStdString(intraop->name()), QString::fromStdString(preop->name()));
  controls_->start(message, [this, fixedImage, movingImage, movingLabels, chosen](CancelFlag cancel) -> BackgroundRun::Delivery {
    QElapsedTimer clock;
    clock.start();
    RigidRegistrationParameters parameters = chosen;
    parameters.cancel = cancel;
    const RigidRegistrationResult result = registerRigidly(*fixedImage, *movingImage, movingLabels.GetPointer(), parameters);
    const double seconds = clock.elapsed() / 1000.0;
    return [this, result, seconds] { finish(result, seconds); };
  });
}

void RigidRegistrationPanel::finish(const RigidRegistrationResult& result, double seconds)
{
  if (!result.trustworthy) {
    controls_->finish(false, tr("Rigid registration cannot be trusted: %1; no transform added.")
                               .arg(QString::fromStdString(result.failureReason)));
    return;
  }
  auto node = scene_.findByName<TransformNode>(resultNodeName().toStdString());
  if (node) {
    node->setTransformFromParent(result.intraopToPreop);
  } else {
    node = scene_.add(TransformNode::create(resultNodeName().toStdString(), result.intraopToPreop));
  }
  QString text = tr("Done in %1 s: rotation %2 degrees, translation %3 mm, NMI %4, overlap %5.")
                   .arg(seconds, 0, 'f', 1)
                   .arg(result.rotationDegrees, 0, 'f', 2)
                   .arg(result.translationMm, 0, 'f', 2)
                   .arg(result.normalizedMutualInformation, 0, 'f', 3)
                   .arg(result.overlap, 0, 'f', 2);
  for (const std::string& warning : result.warnings) text += "\n" + tr("Warning: %1").arg(QString::fromStdString(warning));
  controls_->finish(true, text);
}

} // namespace brainshift
