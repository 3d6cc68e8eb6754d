#include "FusionReviewPanel.h"

#include "Scene.h"
#include "VolumeNodes.h"

#include <QCheckBox>
#include <QComboBox>
#include <QDoubleSpinBox>
#include <QFormLayout>
#include <QLabel>
#include <QSlider>
#include <QTimer>
#include <QVBoxLayout>

#include <algorithm>
#include <cmath>

namespace brainshift {

namespace {
double brightestOf(const ScalarVolumeNode& node)
{
  if (!node.image()) return 0.0;
  const float* v = node.image()->GetBufferPointer();
  const std::size_t n = node.image()->GetLargestPossibleRegion().GetNumberOfPixels();
  return n ? double(*std::max_element(v, v + n)) : 0.0;
}
} // namespace

FusionReviewPanel::FusionReviewPanel(Scene& scene, const ModuleContext& context, QWidget* parent)
  : QWidget(parent)
  , scene_(scene)
  , context_(context)
{
  intraop_ = new NodeSelector({NodeKind::ScalarVolume}, {}, this);
  intraop_->setObjectName("intraopSelector");
  overlay_ = new NodeSelector({NodeKind::ScalarVolume}, "overlay", this);
  overlay_->setObjectName("overlaySelector");
  labels_ = new NodeSelector({NodeKind::LabelMapVolume}, {}, this);
  labels_->setObjectName("labelsSelector");
  comparison_ = new NodeSelector({NodeKind::ScalarVolume}, {}, this);
  comparison_->setObjectName("comparisonSelector");
  overlayKind_ = new QComboBox(this);
  overlayKind_->addItems({tr("fMRI statistics (cold to hot, |t|)"), tr("Angiogram (red)")}); // OverlayKind's order
  threshold_ = new QDoubleSpinBox(this);
  threshold_->setRange(0.0, 1e6);
  threshold_->setDecimals(2);
  threshold_->setValue(3.0);
  threshold_->setToolTip(tr("Overlay values whose magnitude is below this are not shown"));
  opacity_ = new QSlider(Qt::Horizontal, this);
  opacity_->setRange(0, 100);
  opacity_->setValue(70);
  outline_ = new QCheckBox(tr("Labels as outlines"), this);
  outline_->setChecked(true);
  comparisonMode_ = new QComboBox(this);
  comparisonMode_->addItems({tr("Off"), tr("Checkerboard"), tr("Difference"), tr("Flicker")});
  status_ = new QLabel(this);
  status_->setWordWrap(true);

  auto* form = new QFormLayout;
  form->addRow(tr("Intraoperative"), intraop_);
  form->addRow(tr("Overlay"), overlay_);
  form->addRow(tr("Overlay kind"), overlayKind_);
  form->addRow(tr("Threshold"), threshold_);
  form->addRow(tr("Opacity"), opacity_);
  form->addRow(tr("Labels"), labels_);
  form->addRow(QString(), outline_);
  form->addRow(tr("Compare with"), comparison_);
  form->addRow(tr("Comparison"), comparisonMode_);
  auto* column = new QVBoxLayout(this);
  column->addLayout(form);
  column->addWidget(status_);
  column->addStretch(1);

  for (NodeSelector* selector : {intraop_, overlay_, labels_, comparison_}) selector->setScene(&scene_);
  for (const auto& node : scene_.nodes()) chooseByRole(*node);
  sceneObserver_ = scene_.addObserver([this](const SceneEvent& event) {
    // (A loaded scene may give a node its role after adding it.) Once the event is over: the
    // selectors may hear of a new node after this observer does.
    if (event.type != SceneEventType::NodeAdded && event.type != SceneEventType::NodeModified) return;
    QTimer::singleShot(0, this, [this, id = event.node->id()] {
      if (auto node = scene_.node(id)) chooseByRole(*node);
    });
  });
  // Every change shows at once: reading is the point of this panel.
  for (NodeSelector* selector : {intraop_, overlay_, labels_, comparison_}) {
    connect(selector, &NodeSelector::currentNodeChanged, this, &FusionReviewPanel::apply);
  }
  connect(overlayKind_, qOverload<int>(&QComboBox::currentIndexChanged), this, [this](int kind) {
    // A t-map is read from |t| = 3; an angiogram from a fifth of its range.
    if (OverlayKind(kind) == OverlayKind::Statistics) {
      threshold_->setValue(3.0);
    } else if (auto node = std::dynamic_pointer_cast<ScalarVolumeNode>(overlay_->currentNode())) {
      threshold_->setValue(0.2 * brightestOf(*node));
    }
    apply();
  });
  connect(threshold_, qOverload<double>(&QDoubleSpinBox::valueChanged), this, &FusionReviewPanel::apply);
  connect(opacity_, &QSlider::valueChanged, this, &FusionReviewPanel::apply);
  connect(outline_, &QCheckBox::toggled, this, &FusionReviewPanel::apply);
  connect(comparisonMode_, qOverload<int>(&QComboBox::currentIndexChanged), this, &FusionReviewPanel::apply);
  apply();
}

FusionReviewPanel::~FusionReviewPanel()
{
  scene_.removeObserver(sceneObserver_);
  for (NodeSelector* selector : {intraop_, overlay_, labels_, comparison_}) selector->setScene(nullptr);
}

void FusionReviewPanel::chooseByRole(const Node& node)
{
  // A selector whose choice lacks the role takes the first node that has it.
  auto offer = [&node](NodeSelector* selector, const std::string& role) {
    const auto current = selector->currentNode();
    if (node.role() == role && (!current || current->role() != role)) selector->setCurrentNodeId(QString::fromStdString(node.id()));
  };
  if (node.kind() == NodeKind::ScalarVolume) {
    offer(intraop_, "intraop");
    offer(comparison_, "warped");
  } else if (node.kind() == NodeKind::LabelMapVolume) {
    offer(labels_, "warped");
  }
}

void FusionReviewPanel::setOverlayKind(OverlayKind kind) { overlayKind_->setCurrentIndex(int(kind)); }
void FusionReviewPanel::setOverlayThreshold(double threshold) { threshold_->setValue(threshold); }
void FusionReviewPanel::setOverlayOpacity(double opacity) { opacity_->setValue(int(std::lround(100 * opacity))); }
void FusionReviewPanel::setComparison(Comparison comparison) { comparisonMode_->setCurrentIndex(int(comparison)); }
void FusionReviewPanel::setLabelOutline(bool outline) { outline_->setChecked(outline); }
QString FusionReviewPanel::statusText() const { return status_->text(); }

void FusionReviewPanel::apply()
{
  auto overlay = std::dynamic_pointer_cast<ScalarVolumeNode>(overlay_->currentNode());
  if (overlay) {
    VolumeDisplay display = overlay->display();
    const bool statistics = OverlayKind(overlayKind_->currentIndex()) == OverlayKind::Statistics;
    display.colorTable = statistics ? "ColdToHotRainbow" : "Red";
    display.lowerThreshold = threshold_->value();
    display.upperThreshold.reset();
    display.opacity = opacity_->value() / 100.0;
    if (!statistics) { // the angiogram's window: its threshold to its brightest
      const double brightest = brightestOf(*overlay);
      display.window = std::max(1e-6, brightest - threshold_->value());
      display.level = 0.5 * (brightest + threshold_->value());
    }
    overlay->setDisplay(display);
  }
  ViewLayers layers;
  auto idOf = [](NodeSelector* selector) { return selector->currentNodeId().toStdString(); };
  layers.backgroundId = idOf(intraop_);
  layers.overlayId = idOf(overlay_);
  layers.labelMapId = idOf(labels_);
  layers.comparisonId = idOf(comparison_);
  layers.comparisonMode = comparisonMode_->currentIndex();
  layers.labelOutline = outline_->isChecked();
  if (context_.showLayers) context_.showLayers(layers);
  status_->setText(layers.backgroundId.empty()
                     ? tr("No intraoperative volume in the scene yet.")
                     : tr("Showing %1%2%3.")
                         .arg(intraop_->currentText())
                         .arg(overlay ? tr(" with %1 (|value| >= %2)").arg(overlay_->currentText()).arg(threshold_->value()) : QString())
                         .arg(comparisonMode_->currentIndex() > 0
                                ? tr(", compared with %1 (%2)").arg(comparison_->currentText(), comparisonMode_->currentText())
                                : QString()));
  emit applied();
}

} // namespace brainshift
