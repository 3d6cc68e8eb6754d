#include "MeshingPanel.h"

#include <QDoubleSpinBox>
#include <QElapsedTimer>
#include <QFormLayout>
#include <QLineEdit>
#include <QRegularExpression>
#include <QVBoxLayout>

#include <initializer_list>

namespace brainshift {

MeshingPanel::MeshingPanel(Scene& scene, const Configuration& configuration, QWidget* parent)
  : QWidget(parent)
  , scene_(scene)
  , defaults_(meshingParametersFrom(configuration))
{
  labels_ = new NodeSelector({NodeKind::LabelMapVolume}, {}, this);
  labels_->setObjectName("labelsSelector");
  resolution_ = new QDoubleSpinBox(this);
  resolution_->setRange(0.5, 20.0);
  resolution_->setSingleStep(0.5);
  resolution_->setSuffix(" mm");
  resolution_->setValue(defaults_.resolutionMm);
  QStringList tissues;
  for (int label : defaults_.labels) tissues << QString::number(label);
  tissues_ = new QLineEdit(tissues.join(", "), this);
  tissues_->setToolTip(tr("The labels meshed: 2 parenchyma, 3 ventricles, 4 tumour"));
  controls_ = new StageRunControls(tr("Meshing"), this);

  auto* form = new QFormLayout;
  form->addRow(tr("Preoperative labels"), labels_);
  form->addRow(tr("Tissues"), tissues_);
  form->addRow(tr("Resolution"), resolution_);
  auto* column = new QVBoxLayout(this);
  column->addLayout(form);
  column->addWidget(controls_);
  column->addStretch(1);

  labels_->setScene(&scene_);
  connect(controls_, &StageRunControls::runRequested, this, &MeshingPanel::run);
  connect(controls_, &StageRunControls::runningChanged, this, &MeshingPanel::lockInputs);
  connect(controls_, &StageRunControls::finished, this, &MeshingPanel::runFinished);
  connect(controls_, &StageRunControls::discarded, this, &MeshingPanel::discardedRunFinished);
}

MeshingPanel::~MeshingPanel()
{
  labels_->setScene(nullptr);
}

void MeshingPanel::lockInputs(bool locked)
{
  for (QWidget* input : std::initializer_list<QWidget*>{labels_, tissues_, resolution_}) input->setEnabled(!locked);
}

void MeshingPanel::run()
{
  if (isRunning()) return;
  auto labels = std::dynamic_pointer_cast<LabelMapVolumeNode>(labels_->currentNode());
  if (!labels || !labels->image()) {
    controls_->setStatus(tr("Choose a label map first."));
    return;
  }
  MeshingParameters parameters = defaults_;
  parameters.resolutionMm = resolution_->value();
  parameters.labels.clear();
  for (const QString& text : tissues_->text().split(QRegularExpression("[,\\s]+"), Qt::SkipEmptyParts)) {
    bool isNumber = false;
    const int label = text.toInt(&isNumber);
    if (!isNumber || label <= 0) {
      controls_->setStatus(tr("Tissues: '%1' is not a label (a positive whole number).").arg(text));
      return;
    }
    parameters.labels.push_back(label);
  }
  if (parameters.labels.empty()) {
    controls_->setStatus(tr("Tissues: name at least one label."));
    return;
  }
  LabelImage::ConstPointer image = labels->image(); // the worker's own reference (see BackgroundRun.h)
  const QString message = tr("Meshing %1 at %2 mm ...").arg(QString::fromStdString(labels->name())).arg(parameters.resolutionMm);
  controls_->start(message, [this, image, chosen = parameters](CancelFlag cancel) -> BackgroundRun::Delivery {
    QElapsedTimer clock;
    clock.start();
    MeshingParameters parameters = chosen;
    parameters.cancel = cancel;
    const LabelMapMesh result = meshLabelMap(*image, parameters);
    const double seconds = clock.elapsed() / 1000.0;
    return [this, result, seconds] { finish(result, seconds); };
  });
}

void MeshingPanel::finish(const LabelMapMesh& result, double seconds)
{
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
  controls_->finish(true, text);
}

} // namespace brainshift
