#include "TissueClassificationPanel.h"

#include <QComboBox>
#include <QElapsedTimer>
#include <QFormLayout>
#include <QLabel>
#include <QPushButton>
#include <QSpinBox>
#include <QVBoxLayout>

#include <map>

namespace brainshift {

TissueClassificationPanel::TissueClassificationPanel(Scene& scene, const ModuleContext& context, QWidget* parent)
  : QWidget(parent)
  , scene_(scene)
  , defaults_(classificationParametersFrom(Configuration::loadOrDefaults(context.configurationFile)))
{
  intraop_ = new NodeSelector({NodeKind::ScalarVolume}, {}, this);
  preopLabels_ = new NodeSelector({NodeKind::LabelMapVolume}, {}, this);
  preopImage_ = new NodeSelector({NodeKind::ScalarVolume}, "preop", this); // the preoperative MRI, not an overlay
  preopImage_->setToolTip(tr("The preoperative MRI on the labels' grid (the scene's \"preop\" volumes; without one the "
                             "classification runs without it). With it the gap under the craniotomy takes the fluid pooled "
                             "over the sunken brain, and the tumour is compared with its look before surgery"));
  transform_ = new NodeSelector({NodeKind::Transform}, {}, this);
  k_ = new QSpinBox(this);
  k_->setRange(1, 101);
  k_->setValue(int(defaults_.k));
  pickTissue_ = new QComboBox(this);
  for (LabelPixel label = 0; label <= 4; ++label) pickTissue_->addItem(QString::fromStdString(tissueName(label)), int(label));
  pickTissue_->setCurrentIndex(2);
  pick_ = new QPushButton(tr("Pick"), this);
  pick_->setCheckable(true);
  pick_->setObjectName("pickButton");
  pick_->setToolTip(tr("While on, each point picked in a slice view becomes a prototype of the chosen tissue"));
  clear_ = new QPushButton(tr("Clear"), this);
  clear_->setToolTip(tr("Forget the prototypes: the next run chooses them itself"));
  prototypeCounts_ = new QLabel(this);
  prototypeCounts_->setObjectName("prototypeCounts");
  prototypeCounts_->setWordWrap(true);
  controls_ = new StageRunControls(tr("Classification"), this);

  auto* form = new QFormLayout;
  form->addRow(tr("Intraoperative volume"), intraop_);
  form->addRow(tr("Preoperative labels"), preopLabels_);
  form->addRow(tr("Preoperative volume"), preopImage_);
  form->addRow(tr("Rigid intraop_to_preop"), transform_);
  form->addRow(tr("Neighbours (k)"), k_);
  auto* picking = new QHBoxLayout;
  picking->addWidget(pickTissue_, 1);
  picking->addWidget(pick_);
  picking->addWidget(clear_);
  form->addRow(tr("Prototypes"), picking);
  form->addRow(QString(), prototypeCounts_);
  auto* column = new QVBoxLayout(this);
  column->addLayout(form);
  column->addWidget(controls_);
  column->addStretch(1);

  intraop_->setScene(&scene_);
  preopLabels_->setScene(&scene_);
  preopImage_->setScene(&scene_);
  transform_->setScene(&scene_);
  for (const auto& volume : scene_.nodesOfType<ScalarVolumeNode>()) {
    if (volume->role() == "intraop") intraop_->setCurrentNodeId(QString::fromStdString(volume->id()));
  }
  if (context.subscribeToPicks) {
    context.subscribeToPicks(this, [this](const std::array<double, 3>& lps) {
      if (pick_->isChecked() && !isRunning()) addPrototype(lps);
    });
  } else {
    pick_->setEnabled(false);
  }
  connect(clear_, &QPushButton::clicked, this, &TissueClassificationPanel::clearPrototypes);
  connect(controls_, &StageRunControls::runRequested, this, &TissueClassificationPanel::run);
  connect(controls_, &StageRunControls::runningChanged, this, &TissueClassificationPanel::lockInputs);
  connect(controls_, &StageRunControls::finished, this, &TissueClassificationPanel::runFinished);
  connect(controls_, &StageRunControls::discarded, this, &TissueClassificationPanel::discardedRunFinished);
  showPrototypeCounts();
}

TissueClassificationPanel::~TissueClassificationPanel()
{
  intraop_->setScene(nullptr);
  preopLabels_->setScene(nullptr);
  preopImage_->setScene(nullptr);
  transform_->setScene(nullptr);
}

void TissueClassificationPanel::lockInputs(bool locked)
{
  for (QWidget* input : std::initializer_list<QWidget*>{intraop_, preopLabels_, preopImage_, transform_, k_, clear_}) input->setEnabled(!locked);
}

void TissueClassificationPanel::addPrototype(const std::array<double, 3>& lps)
{
  const auto label = LabelPixel(pickTissue_->currentData().toInt());
  TissuePrototype prototype;
  prototype.name = tissueName(label) + "-picked-" + std::to_string(++picks_);
  prototype.label = label;
  for (int i = 0; i < 3; ++i) prototype.position[i] = lps[i];
  prototypes_.push_back(prototype);
  showPrototypeCounts();
}

void TissueClassificationPanel::clearPrototypes()
{
  prototypes_.clear();
  showPrototypeCounts();
}

void TissueClassificationPanel::showPrototypeCounts()
{
  if (prototypes_.empty()) {
    prototypeCounts_->setText(tr("None listed: the run chooses them."));
    return;
  }
  std::map<LabelPixel, int> counts;
  for (const TissuePrototype& p : prototypes_) counts[p.label] += 1;
  QStringList parts;
  for (const auto& [label, count] : counts) parts << QString("%1 %2").arg(QString::fromStdString(tissueName(label))).arg(count);
  prototypeCounts_->setText(tr("Listed: %1 (%2 picked)").arg(parts.join(", ")).arg(picks_));
}

void TissueClassificationPanel::run()
{
  if (isRunning()) return;
  auto intraop = std::dynamic_pointer_cast<ScalarVolumeNode>(intraop_->currentNode());
  auto labels = std::dynamic_pointer_cast<LabelMapVolumeNode>(preopLabels_->currentNode());
  auto transform = std::dynamic_pointer_cast<TransformNode>(transform_->currentNode());
  if (!intraop || !intraop->image() || !labels || !labels->image() || !transform || !transform->transformFromParent()) {
    controls_->setStatus(tr("Choose the intraoperative volume, the preoperative labels and the rigid transform first."));
    return;
  }
  TissueClassificationParameters parameters = defaults_;
  parameters.k = unsigned(k_->value());
  parameters.prototypesPerClass = std::max(parameters.prototypesPerClass, parameters.k);
  // The worker's own references (see BackgroundRun.h); the list is copied.
  ScalarImage::ConstPointer image = intraop->image();
  LabelImage::ConstPointer preopLabels = labels->image();
  SpatialTransform::ConstPointer rigid = transform->transformFromParent();
  auto preop = std::dynamic_pointer_cast<ScalarVolumeNode>(preopImage_->currentNode());
  ScalarImage::ConstPointer preopImage = preop ? preop->image() : nullptr;
  std::optional<std::vector<TissuePrototype>> given;
  if (!prototypes_.empty()) given = prototypes_;
  const QString message = given ? tr("Classifying with %1 listed prototypes ...").arg(given->size())
                                : tr("Classifying with automatic prototypes ...");
  controls_->start(message, [this, image, preopLabels, preopImage, rigid, given, chosen = parameters](CancelFlag cancel) -> BackgroundRun::Delivery {
    QElapsedTimer clock;
    clock.start();
    TissueClassificationParameters parameters = chosen;
    parameters.cancel = cancel;
    if (preopImage) takePreoperativeImage(parameters, *preopImage, *preopLabels, *rigid);
    const TissueClassificationResult result = classifyTissues(*image, *preopLabels, *rigid, given, parameters);
    const double seconds = clock.elapsed() / 1000.0;
    return [this, result, seconds] { finish(result, seconds); };
  });
}

void TissueClassificationPanel::finish(const TissueClassificationResult& result, double seconds)
{
  auto node = scene_.findByName<LabelMapVolumeNode>(resultNodeName().toStdString());
  if (node) {
    node->setImage(result.labels);
  } else {
    node = LabelMapVolumeNode::create(resultNodeName().toStdString(), result.labels);
    node->setRole("intraop");
    scene_.add(node);
  }
  prototypes_ = result.prototypes; // what was used: the list to correct for the next run
  showPrototypeCounts();
  QString text = tr("Done in %1 s: %2 voxels, %3 prototypes%4.")
                   .arg(seconds, 0, 'f', 1)
                   .arg(result.voxels)
                   .arg(result.prototypes.size())
                   .arg(result.tumourResected ? tr("; the tumour looks resected") : QString());
  for (const std::string& warning : result.warnings) text += "\n" + tr("Warning: %1").arg(QString::fromStdString(warning));
  controls_->finish(true, text);
}

} // namespace brainshift
