#include "DataPanel.h"

#include <QCheckBox>
#include <QComboBox>
#include <QDoubleSpinBox>
#include <QFormLayout>
#include <QLabel>
#include <QListView>
#include <QSlider>
#include <QVBoxLayout>

namespace brainshift {

DataPanel::DataPanel(Scene& scene, ViewLayout& views, QWidget* parent)
  : QWidget(parent)
  , scene_(scene)
  , views_(views)
{
  background_ = new NodeSelector({NodeKind::ScalarVolume}, {}, this);
  labelMap_ = new NodeSelector({NodeKind::LabelMapVolume}, {}, this);
  overlay_ = new NodeSelector({NodeKind::ScalarVolume}, "overlay", this);
  comparison_ = new NodeSelector({NodeKind::ScalarVolume}, {}, this);
  comparisonMode_ = new QComboBox(this);
  comparisonMode_->addItems({tr("Off"), tr("Checkerboard"), tr("Difference"), tr("Flicker")}); // ComparisonMode's order
  labelOutline_ = new QCheckBox(tr("Outline"), this);
  labelOpacity_ = new QSlider(Qt::Horizontal, this);
  labelOpacity_->setRange(0, 100);
  labelOpacity_->setValue(50);
  overlayOpacity_ = new QSlider(Qt::Horizontal, this);
  overlayOpacity_->setRange(0, 100);
  overlayOpacity_->setValue(70);
  overlayThreshold_ = new QDoubleSpinBox(this);
  overlayThreshold_->setRange(0.0, 1e6);
  overlayThreshold_->setDecimals(2);
  overlayThreshold_->setToolTip(tr("Overlay values with a magnitude below this are hidden"));
  nodes_ = new QListView(this);
  auto* allNodes = new SceneNodeModel({}, {}, nodes_);
  allNodes->setScene(&scene_);
  nodes_->setModel(allNodes);

  auto* form = new QFormLayout;
  form->addRow(tr("Background"), background_);
  form->addRow(tr("Label map"), labelMap_);
  form->addRow(tr("Label opacity"), labelOpacity_);
  form->addRow(QString(), labelOutline_);
  form->addRow(tr("Overlay"), overlay_);
  form->addRow(tr("Overlay threshold"), overlayThreshold_);
  form->addRow(tr("Overlay opacity"), overlayOpacity_);
  form->addRow(tr("Compare with"), comparison_);
  form->addRow(tr("Comparison"), comparisonMode_);
  auto* column = new QVBoxLayout(this);
  column->addLayout(form);
  column->addWidget(new QLabel(tr("Scene"), this));
  column->addWidget(nodes_, 1);

  background_->setScene(&scene_);
  labelMap_->setScene(&scene_);
  overlay_->setScene(&scene_);
  comparison_->setScene(&scene_);
  connect(comparison_, &NodeSelector::currentNodeChanged, this, [this] {
    views_.setComparison(std::dynamic_pointer_cast<ScalarVolumeNode>(comparison_->currentNode()));
  });
  connect(comparisonMode_, qOverload<int>(&QComboBox::currentIndexChanged), this,
          [this](int index) { views_.setComparisonMode(ComparisonMode(index)); });
  connect(labelOutline_, &QCheckBox::toggled, this, [this](bool outline) { views_.setLabelOutline(outline); });
  connect(background_, &NodeSelector::currentNodeChanged, this, &DataPanel::showChosenLayers);
  connect(labelMap_, &NodeSelector::currentNodeChanged, this, &DataPanel::showChosenLayers);
  connect(overlay_, &NodeSelector::currentNodeChanged, this, [this] {
    if (auto node = std::dynamic_pointer_cast<ScalarVolumeNode>(overlay_->currentNode())) {
      const QSignalBlocker blockThreshold(overlayThreshold_), blockOpacity(overlayOpacity_);
      overlayThreshold_->setValue(node->display().lowerThreshold.value_or(0.0));
      overlayOpacity_->setValue(int(std::lround(100 * node->display().opacity)));
    }
    showChosenLayers();
  });
  connect(labelOpacity_, &QSlider::valueChanged, this, [this](int value) {
    for (auto orientation : {SliceOrientation::Axial, SliceOrientation::Sagittal, SliceOrientation::Coronal}) {
      views_.sliceView(orientation)->setLabelOpacity(value / 100.0);
    }
  });
  connect(overlayOpacity_, &QSlider::valueChanged, this, &DataPanel::applyOverlayDisplay);
  connect(overlayThreshold_, qOverload<double>(&QDoubleSpinBox::valueChanged), this, &DataPanel::applyOverlayDisplay);
  showChosenLayers();
}

DataPanel::~DataPanel()
{
  background_->setScene(nullptr);
  labelMap_->setScene(nullptr);
  overlay_->setScene(nullptr);
  comparison_->setScene(nullptr);
  static_cast<SceneNodeModel*>(nodes_->model())->setScene(nullptr);
}

void DataPanel::showChosenLayers()
{
  auto background = std::dynamic_pointer_cast<ScalarVolumeNode>(background_->currentNode());
  auto labels = std::dynamic_pointer_cast<LabelMapVolumeNode>(labelMap_->currentNode());
  auto overlay = std::dynamic_pointer_cast<ScalarVolumeNode>(overlay_->currentNode());
  // An overlay is not its own background.
  if (background && background == overlay) overlay = nullptr;
  SliceView* axial = views_.sliceView(SliceOrientation::Axial);
  if (axial->background() != background) views_.setBackground(background);
  if (axial->labelMap() != labels) views_.setLabelMap(labels);
  if (axial->overlay() != overlay) views_.setOverlay(overlay);
}

void DataPanel::applyOverlayDisplay()
{
  auto node = std::dynamic_pointer_cast<ScalarVolumeNode>(overlay_->currentNode());
  if (!node) return;
  VolumeDisplay display = node->display();
  display.lowerThreshold = overlayThreshold_->value();
  display.opacity = overlayOpacity_->value() / 100.0;
  node->setDisplay(display);
  views_.updateLayers();
}

} // namespace brainshift
