#pragma once
// The fusion and review panel, for the radiologist reading the preoperative data brought onto the
// intraoperative scan: the intraoperative volume as background, one warped overlay (fMRI
// statistics on a cold-to-hot scale thresholded on |t|, or an angiogram on a red scale) with its
// threshold and opacity, the warped labels filled or outlined, and the warped preoperative image
// compared with the intraoperative one (checkerboard, difference or flicker). It binds these scene
// nodes to the views (ModuleContext::showLayers) and writes the overlay's display into its node,
// and nothing more. After `register`, the scene's roles choose every input by themselves.
#include "ModulePlugin.h"
#include "NodeSelector.h"

#include <QWidget>

class QCheckBox;
class QComboBox;
class QDoubleSpinBox;
class QLabel;
class QSlider;

namespace brainshift {

class FusionReviewPanel : public QWidget {
  Q_OBJECT
public:
  enum class OverlayKind { Statistics, Angiography };
  enum class Comparison { Off, Checkerboard, Difference, Flicker }; ///< SliceView's ComparisonMode order

  FusionReviewPanel(Scene& scene, const ModuleContext& context, QWidget* parent = nullptr);
  ~FusionReviewPanel() override;

  NodeSelector* intraopSelector() const { return intraop_; }
  NodeSelector* overlaySelector() const { return overlay_; }
  NodeSelector* labelsSelector() const { return labels_; }
  NodeSelector* comparisonSelector() const { return comparison_; }
  void setOverlayKind(OverlayKind kind);
  void setOverlayThreshold(double threshold);
  void setOverlayOpacity(double opacity); ///< 0 to 1
  void setComparison(Comparison comparison);
  void setLabelOutline(bool outline);
  QString statusText() const;

public slots:
  /// Shows the chosen layers in the views and the overlay's display in its node.
  void apply();

signals:
  void applied();

private:
  void chooseByRole(const Node& node);

  Scene& scene_;
  ModuleContext context_;
  NodeSelector *intraop_, *overlay_, *labels_, *comparison_;
  QComboBox *overlayKind_, *comparisonMode_;
  QDoubleSpinBox* threshold_;
  QSlider* opacity_;
  QCheckBox* outline_;
  QLabel* status_;
  Scene::ObserverId sceneObserver_ = 0;
};

} // namespace brainshift
