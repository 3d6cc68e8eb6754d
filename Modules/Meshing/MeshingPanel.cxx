#include "MeshingPanel.h"

#include <QDoubleSpinBox>
#include <QElapsedTimer>
#include <QFormLayout>
#include <QLabel>
#include <QLineEdit>
#include <QProgressBar>
#include <QPushButton>
#include <QRegularExpression>
#include <QVBoxLayout>

namespace brainshift {

MeshingPanel::MeshingPanel(Scene& scene, QWidget* parent)
  : QWidget(parent)
  , scene_(scene)
{
  labels_ = new NodeSelector({NodeKind::LabelMapVolume}, {}, this);
  labels_->setObjectName("labelsSelector");
  resolution_ = new QDoubleSpinBox(this);
  resolution_->setRange(0.5, 20.0);
  resolution_->setSingleStep(0.5);
  resolution_->setSuffix(" mm");
  resolution_->setValue(MeshingParameters{}.resolutionMm);
  tissues_ = new QLineEdit("2, 3, 4", this);
  tissues_->setToolTip(tr("The labels meshed: 2 parenchyma, 3 ventricles, 4 tumour"));
  run_ = new QPushButton(tr("Run"), this);
  run_->setObjectName("runButton");
  cancel_ = new QPushButton(tr("Cancel"), this);
  progress_ = new QProgressBar(this);
  progress_->setTextVisible(false);
  status_ = new QLabel(tr("Idle"), this);
  status_->setWordWrap(true);
  work_ = new BackgroundRun(this);

  auto* form = new QFormLayout;
  form->addRow(tr("Preoperative labels"), labels_);
  form->addRow(tr("Tissues"), tissues_);
  form->addRow(tr("Resolution"), resolution_);
  auto* buttons = new QHBoxLayout;
  buttons->addWidget(run_);
  buttons->addWidget(cancel_);
  auto* column = new QVBoxLayout(this);
  column->addLayout(form);
  column->addLayout(buttons);
  column->addWidget(progress_);
  column->addWidget(status_);
  column->addStretch(1);

  labels_->setScene(&scene_);
  connect(run_, &QPushButton::clicked, this, &MeshingPanel::run);
  connect(cancel_, &QPushButton::clicked, this, &MeshingPanel::cancel);
  connect(work_, &BackgroundRun::failed, this, [this](const QString& message) {
    setRunning(false);
    status_->setText(tr("Meshing failed: %1").arg(message));
    emit runFinished(false);
  });
  connect(work_, &BackgroundRun::discarded, this, &MeshingPanel::discardedRunFinished);
  setRunning(false);
}

MeshingPanel::~MeshingPanel()
{
  labels_->setScene(nullptr);
}

QString MeshingPanel::statusText() const
{
  return status_->text();
}

void MeshingPanel::setRunning(bool running)
{
  run_->setEnabled(!running);
  cancel_->setEnabled(running);
  labels_->setEnabled(!running);
  tissues_->setEnabled(!running);
  resolution_->setEnabled(!running);
  progress_->setRange(0, running ? 0 : 1); // no progress fraction from the logic: a busy bar
  progress_->setValue(0);
}

void MeshingPanel::run()
{
  if (isRunning()) return;
  auto labels = std::dynamic_pointer_cast<LabelMapVolumeNode>(labels_->currentNode());
  if (!labels || !labels->image()) {
    status_->setText(tr("Choose a label map first."));
    return;
  }
  MeshingParameters parameters;
  parameters.resolutionMm = resolution_->value();
  parameters.labels.clear();
  for (const QString& text : tissues_->text().split(QRegularExpression("[,\\s]+"), Qt::SkipEmptyParts)) {
    bool isNumber = false;
    const int label = text.toInt(&isNumber);
    if (!isNumber || label <= 0) {
      status_->setText(tr("Tissues: '%1' is not a label (a positive whole number).").arg(text));
      return;
    }
    parameters.labels.push_back(label);
  }
  if (parameters.labels.empty()) {
    status_->setText(tr("Tissues: name at least one label."));
    return;
  }
  LabelImage::ConstPointer image = labels->image(); // the worker's own reference (see BackgroundRun.h)
  work_->start([this, image, chosen = parameters](CancelFlag cancel) -> BackgroundRun::Delivery {
    QElapsedTimer clock;
    clock.start();
    MeshingParameters parameters = chosen;
    parameters.cancel = cancel;
    const LabelMapMesh result = meshLabelMap(*image, parameters);
    const double seconds = clock.elapsed() / 1000.0;
    return [this, result, seconds] { finish(result, seconds); };
  });
  setRunning(true);
  status_->setText(tr("Meshing %1 at %2 mm ...").arg(QString::fromStdString(labels->name())).arg(parameters.resolutionMm));
}

void MeshingPanel::cancel()
{
  if (!isRunning()) return;
  work_->cancel();
  setRunning(false);
  status_->setText(tr("Cancelled."));
}

void MeshingPanel::finish(const LabelMapMesh& result, double seconds)
{
  setRunning(false);
  auto node = scene_.findByName<ModelNode>(resultNodeName().toStdString());
  if (node) {
    node->setMesh(result.mesh);
  } else {
    node = ModelNode::create(resultNodeName().toStdString(), result.mesh);
    node->setRole("preop");
    // The model frame: under the rigid transform, when there is one, to overlay the intraop scan.
    if (auto rigid = scene_.findByName<TransformNode>("rigid intraop_to_preop")) node->setParentTransformId(rigid->id());
    scene_.add(node);
  }
  const MeshQuality& q = result.quality;
  QString text = tr("Done in %1 s: %2 nodes, %3 tetrahedra, dihedral angles %4 to %5 degrees, %6 inverted.")
                   .arg(seconds, 0, 'f', 1)
                   .arg(q.nodes)
                   .arg(q.tetrahedra)
                   .arg(q.minimumDihedralDegrees, 0, 'f', 0)
                   .arg(q.maximumDihedralDegrees, 0, 'f', 0)
                   .arg(q.invertedOrFlat);
  for (const std::string& warning : result.warnings) text += "\n" + tr("Warning: %1").arg(QString::fromStdString(warning));
  status_->setText(text);
  emit runFinished(true);
}

} // namespace brainshift
