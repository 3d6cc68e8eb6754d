#pragma once
// The host's own panel: which volumes the slice views show (background, label map, overlay), the
// label map's opacity and the overlay's threshold and opacity (kept in the overlay node's display).
#include "NodeSelector.h"
#include "ViewLayout.h"

#include <QWidget>

class QCheckBox;
class QComboBox;
class QDoubleSpinBox;
class QListView;
class QSlider;

namespace brainshift {

class DataPanel : public QWidget {
  Q_OBJECT
public:
  DataPanel(Scene& scene, ViewLayout& views, QWidget* parent = nullptr);
  ~DataPanel() override;

  NodeSelector* backgroundSelector() const { return background_; }
  NodeSelector* labelMapSelector() const { return labelMap_; }
  NodeSelector* overlaySelector() const { return overlay_; }
  NodeSelector* comparisonSelector() const { return comparison_; }
  QComboBox* comparisonModeBox() const { return comparisonMode_; }
  QCheckBox* labelOutlineBox() const { return labelOutline_; }

private:
  void showChosenLayers();
  void applyOverlayDisplay();

  Scene& scene_;
  ViewLayout& views_;
  NodeSelector *background_, *labelMap_, *overlay_, *comparison_;
  QComboBox* comparisonMode_;
  QCheckBox* labelOutline_;
  QSlider *labelOpacity_, *overlayOpacity_;
  QDoubleSpinBox* overlayThreshold_;
  QListView* nodes_;
};

} // namespace brainshift
