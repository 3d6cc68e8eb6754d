#include "RigidRegistrationPanel.h"

#include <QCheckBox>
#include <QElapsedTimer>
#include <QFormLayout>
#include <QLabel>
#include <QProgressBar>
#include <QPushButton>
#include <QVBoxLayout>


namespace brainshift {

RigidRegistrationPanel::RigidRegistrationPanel(Scene& scene, QWidget* parent)
  : QWidget(parent)
  , scene_(scene)
{
  intraop_ = new NodeSelector({NodeKind::ScalarVolume}, {}, this);
  intraop_->setObjectName("intraopSelector");
  preop_ = new NodeSelector({NodeKind::ScalarVolume}, {}, this);
  preop_->setObjectName("preopSelector");
  preopLabels_ = new NodeSelector({NodeKind::LabelMapVolume}, {}, this);
  preopLabels_->setObjectName("preopLabelsSelector");
  useLabels_ = new QCheckBox(tr("Mask the metric with the labels"), this);
  run_ = new QPushButton(tr("Run"), this);
  cancel_ = new QPushButton(tr("Cancel"), this);
  progress_ = new QProgressBar(this);
  progress_->setTextVisible(false);
  status_ = new QLabel(tr("Idle"), this);
  status_->setWordWrap(true);
  status_->setObjectName("status");
  work_ = new BackgroundRun(this);
  connect(work_, &BackgroundRun::failed, this, [this](const QString& message) {
    setRunning(false);
    setStatus(tr("Rigid registration failed: %1").arg(message));
    emit runFinished(false);
  });
  connect(work_, &BackgroundRun::discarded, this, &RigidRegistrationPanel::discardedRunFinished);

  auto* form = new QFormLayout;
  form->addRow(tr("Intraoperative (fixed)"), intraop_);
  form->addRow(tr("Preoperative (moving)"), preop_);
  form->addRow(tr("Preoperative labels"), preopLabels_);
  form->addRow(useLabels_);
  auto* buttons = new QHBoxLayout;
  buttons->addWidget(run_);
  buttons->addWidget(cancel_);
  auto* column = new QVBoxLayout(this);
  column->addLayout(form);
  column->addLayout(buttons);
  column->addWidget(progress_);
  column->addWidget(status_);
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

  connect(run_, &QPushButton::clicked, this, &RigidRegistrationPanel::run);
  connect(cancel_, &QPushButton::clicked, this, &RigidRegistrationPanel::cancel);
  setRunning(false);
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

QString RigidRegistrationPanel::statusText() const
{
  return status_->text();
}

void RigidRegistrationPanel::setStatus(const QString& text)
{
  status_->setText(text);
}

void RigidRegistrationPanel::setRunning(bool running)
{
  run_->setEnabled(!running);
  cancel_->setEnabled(running);
  intraop_->setEnabled(!running);
  preop_->setEnabled(!running);
  preopLabels_->setEnabled(!running);
  useLabels_->setEnabled(!running);
  // No progress fraction from the logic: a busy bar while running, empty when idle.
  progress_->setRange(0, running ? 0 : 1);
  progress_->setValue(0);
}

void RigidRegistrationPanel::run()
{
  if (isRunning()) return;
  auto intraop = std::dynamic_pointer_cast<ScalarVolumeNode>(intraop_->currentNode());
  auto preop = std::dynamic_pointer_cast<ScalarVolumeNode>(preop_->currentNode());
  if (!intraop || !preop || !intraop->image() || !preop->image()) {
    setStatus(tr("Choose an intraoperative and a preoperative volume first."));
    return;
  }
  if (intraop == preop) {
    setStatus(tr("The intraoperative and the preoperative volume are the same node."));
    return;
  }
  auto labels = useLabels_->isChecked() ? std::dynamic_pointer_cast<LabelMapVolumeNode>(preopLabels_->currentNode()) : nullptr;

  // The worker holds its own references to the images: the scene may change meanwhile (nodes
  // replace images rather than edit them in place), and nothing of the scene is touched off
  // the GUI thread.
  ScalarImage::ConstPointer fixedImage = intraop->image(), movingImage = preop->image();
  LabelImage::ConstPointer movingLabels = labels ? labels->image() : nullptr;
  const RigidRegistrationParameters chosen = parameters_;
  work_->start([this, fixedImage, movingImage, movingLabels, chosen](CancelFlag cancel) -> BackgroundRun::Delivery {
    QElapsedTimer clock;
    clock.start();
    RigidRegistrationParameters parameters = chosen;
    parameters.cancel = cancel;
    const RigidRegistrationResult result = registerRigidly(*fixedImage, *movingImage, movingLabels.GetPointer(), parameters);
    const double seconds = clock.elapsed() / 1000.0;
    return [this, result, seconds] { finish(result, seconds); };
  });
  setRunning(true);
  setStatus(tr("Registering %1 to %2 ...").arg(QString::fromStdString(intraop->name()), QString::fromStdString(preop->name())));
}

void RigidRegistrationPanel::cancel()
{
  if (!isRunning()) return;
  work_->cancel();
  setRunning(false);
  setStatus(tr("Cancelled."));
}

void RigidRegistrationPanel::finish(const RigidRegistrationResult& result, double seconds)
{
  setRunning(false);
  if (!result.trustworthy) {
    setStatus(tr("Rigid registration cannot be trusted: %1; no transform added.").arg(QString::fromStdString(result.failureReason)));
    emit runFinished(false);
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
  setStatus(text);
  emit runFinished(true);
}

} // namespace brainshift
