#pragma once
// A slice view: one plane (axial, sagittal or coronal) through up to three layers of the scene,
// composed bottom to top: a scalar background with window/level, a label map filled with an
// opacity, and an overlay (fMRI statistics, MRA) with a colour map, threshold and opacity as its
// node's VolumeDisplay says. A cursor (cross-hair) marks a point; clicking moves it, the wheel
// moves the slice, dragging with the right button changes window/level. All positions are LPS mm
// (see ImageConversion.h).
#include "ImageConversion.h"
#include "VolumeNodes.h"

#include <QVTKOpenGLNativeWidget.h>

#include <QMetaType>

#include <array>
#include <memory>
#include <optional>

class vtkImageActor;
class vtkActor;
class vtkPolyData;
class vtkRenderer;
class QTimer;

namespace brainshift {

enum class SliceOrientation { Axial, Sagittal, Coronal };
QString toString(SliceOrientation orientation);

/// How the comparison volume (say the warped preoperative scan) is shown against the background
/// (the intraoperative scan): not at all, in alternating squares, as their difference (mid grey:
/// equal), or in turns (flicker, twice a second).
enum class ComparisonMode { Off, Checkerboard, Difference, Flicker };

class SliceView : public QVTKOpenGLNativeWidget {
  Q_OBJECT
public:
  explicit SliceView(SliceOrientation orientation, QWidget* parent = nullptr);
  ~SliceView() override;
  SliceOrientation orientation() const { return orientation_; }

  /// The layers (null: none). The view keeps the nodes alive; call updateLayers() after a
  /// node's data or display changed.
  void setBackground(std::shared_ptr<ScalarVolumeNode> node);
  void setLabelMap(std::shared_ptr<LabelMapVolumeNode> node);
  void setOverlay(std::shared_ptr<ScalarVolumeNode> node);
  const std::shared_ptr<ScalarVolumeNode>& background() const { return background_; }
  const std::shared_ptr<LabelMapVolumeNode>& labelMap() const { return labelMap_; }
  const std::shared_ptr<ScalarVolumeNode>& overlay() const { return overlay_; }
  void updateLayers();

  /// The background's window and level (the node's, or automatic from its range until set here).
  void setWindowLevel(double window, double level);
  std::array<double, 2> windowLevel() const { return {window_, level_}; }
  void setLabelOpacity(double opacity);
  double labelOpacity() const { return labelOpacity_; }
  /// Labels as outlines (the pixels with a differently labelled neighbour) instead of filled.
  void setLabelOutline(bool outline);
  bool labelOutline() const { return labelOutline_; }

  /// The volume compared with the background, on the background's window/level.
  void setComparison(std::shared_ptr<ScalarVolumeNode> node);
  const std::shared_ptr<ScalarVolumeNode>& comparison() const { return comparison_; }
  void setComparisonMode(ComparisonMode mode);
  ComparisonMode comparisonMode() const { return comparisonMode_; }
  /// The checkerboard's square, mm.
  void setCheckerSize(double millimetres);
  /// Flicker: whether the comparison volume is the one shown now (the timer toggles it).
  void setFlickerShowsComparison(bool showsComparison);
  bool flickerShowsComparison() const { return flickerShowsComparison_; }

  /// Moves the slice through `p` and the cross-hair onto it.
  void setCursorPosition(const PhysicalPoint& p);
  const PhysicalPoint& cursorPosition() const { return cursor_; }
  /// The LPS point shown at a pixel of the widget (on the current slice).
  PhysicalPoint pointAtPixel(const QPoint& pixel) const;
  /// The composed colour (RGBA) shown at `p` on the current slice; nothing off the slice.
  std::optional<std::array<unsigned char, 4>> colorAt(const PhysicalPoint& p) const;
  const SlicePlane& plane() const { return plane_; }

signals:
  /// The user put the cursor on `p` (a click, or the wheel moving the slice).
  void cursorPicked(const brainshift::PhysicalPoint& p);

protected:
  void mousePressEvent(QMouseEvent* event) override;
  void mouseMoveEvent(QMouseEvent* event) override;
  void wheelEvent(QWheelEvent* event) override;

private:
  void fitPlaneToLayers();
  void resetCamera();
  void reslice();
  void updateCrossHair();

  SliceOrientation orientation_;
  std::shared_ptr<ScalarVolumeNode> background_, overlay_;
  std::shared_ptr<LabelMapVolumeNode> labelMap_;
  std::shared_ptr<ScalarVolumeNode> comparison_;
  ResliceableVolume backgroundVolume_, labelVolume_, overlayVolume_, comparisonVolume_;
  ComparisonMode comparisonMode_ = ComparisonMode::Off;
  double checkerSize_ = 20.0;
  bool flickerShowsComparison_ = false;
  QTimer* flicker_;
  bool labelOutline_ = false;
  std::array<double, 2> backgroundRange_{0, 1}, overlayRange_{0, 1};
  double window_ = 1, level_ = 0.5;
  bool windowLevelSetHere_ = false;
  double labelOpacity_ = 0.5;
  SlicePlane plane_;
  PhysicalPoint cursor_;
  QPoint dragStart_;
  std::array<double, 2> dragStartWindowLevel_{};

  vtkRenderer* renderer_;
  vtkImageActor* imageActor_;
  vtkActor* crossHairActor_;
  vtkPolyData* crossHair_;
  vtkSmartPointer<vtkImageData> composed_;
};

} // namespace brainshift

Q_DECLARE_METATYPE(brainshift::PhysicalPoint)
