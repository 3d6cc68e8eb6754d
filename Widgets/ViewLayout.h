#pragma once
// The host's views: axial, sagittal and coronal slice views and a 3D view, four-up or one of
// them alone, with one cursor shared by the slice views (a click in one moves the others to the
// point) and a readout of the cursor's LPS position and each layer's value there.
#include "LayerReadout.h"
#include "SliceView.h"
#include "ThreeDView.h"

#include <QWidget>

#include <array>

class QGridLayout;
class QLabel;

namespace brainshift {

enum class ViewArrangement { FourUp, OneUpAxial, OneUpSagittal, OneUpCoronal, OneUp3D };

class ViewLayout : public QWidget {
  Q_OBJECT
public:
  explicit ViewLayout(QWidget* parent = nullptr);

  void setArrangement(ViewArrangement arrangement);
  ViewArrangement arrangement() const { return arrangement_; }

  SliceView* sliceView(SliceOrientation orientation) const;
  ThreeDView* threeDView() const { return threeD_; }

  /// The layers of every slice view (null: none).
  void setBackground(std::shared_ptr<ScalarVolumeNode> node);
  void setLabelMap(std::shared_ptr<LabelMapVolumeNode> node);
  void setOverlay(std::shared_ptr<ScalarVolumeNode> node);
  /// The volume compared with the background, and how (see ComparisonMode).
  void setComparison(std::shared_ptr<ScalarVolumeNode> node);
  void setComparisonMode(ComparisonMode mode);
  void setLabelOutline(bool outline);
  /// After a layer's data or display changed.
  void updateLayers();

  /// Moves every slice view's cursor to `p` and updates the readout.
  void setCursorPosition(const PhysicalPoint& p);
  PhysicalPoint cursorPosition() const { return cursor_; }
  /// The layers' values at the cursor, bottom layer first (background, labels, overlay, and the
  /// comparison volume while a comparison is shown).
  std::vector<LayerValue> valuesAtCursor() const;
  QString readoutText() const;

signals:
  /// The cursor moved (a pick, or setCursorPosition).
  void cursorMoved(const brainshift::PhysicalPoint& p);
  /// The user picked `p` in a slice view (a click, a drag, the wheel).
  void pointPicked(const brainshift::PhysicalPoint& p);

private:
  void updateReadout();
  void updateSlicePlanes(); ///< the 3D view's planes through the cursor, across the background

  std::array<SliceView*, 3> slices_;
  ThreeDView* threeD_;
  QGridLayout* grid_;
  QLabel* readout_;
  ViewArrangement arrangement_ = ViewArrangement::FourUp;
  PhysicalPoint cursor_;
};

} // namespace brainshift
