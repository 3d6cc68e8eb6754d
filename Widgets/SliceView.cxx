#include "SliceView.h"

#include <vtkActor.h>
#include <vtkCamera.h>
#include <vtkCellArray.h>
#include <vtkFloatArray.h>
#include <vtkGenericOpenGLRenderWindow.h>
#include <vtkImageActor.h>
#include <vtkImageData.h>
#include <vtkInteractorStyleUser.h>
#include <vtkLookupTable.h>
#include <vtkMath.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkProperty.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkRenderer.h>
#include <vtkUnsignedCharArray.h>

#include <QMouseEvent>
#include <QTimer>
#include <QWheelEvent>

#include <algorithm>
#include <cmath>
#include <limits>

namespace brainshift {

QString toString(SliceOrientation orientation)
{
  switch (orientation) {
  case SliceOrientation::Axial: return "Axial";
  case SliceOrientation::Sagittal: return "Sagittal";
  case SliceOrientation::Coronal: return "Coronal";
  }
  return {};
}

namespace {
/// The plane axes in LPS, radiological: axial and coronal show the patient's left on the right of
/// the screen; axial has anterior up, coronal and sagittal superior up; sagittal has anterior right.
SlicePlane planeFor(SliceOrientation orientation)
{
  SlicePlane plane;
  switch (orientation) {
  case SliceOrientation::Axial: plane.axisU = {1, 0, 0}; plane.axisV = {0, -1, 0}; plane.normal = {0, 0, -1}; break;
  case SliceOrientation::Coronal: plane.axisU = {1, 0, 0}; plane.axisV = {0, 0, 1}; plane.normal = {0, -1, 0}; break;
  case SliceOrientation::Sagittal: plane.axisU = {0, -1, 0}; plane.axisV = {0, 0, 1}; plane.normal = {-1, 0, 0}; break;
  }
  return plane;
}

/// The contract's labels in the colours a radiologist expects; other labels get distinct hues.
std::array<double, 3> labelColor(int label)
{
  switch (label) {
  case 1: return {0.85, 0.75, 0.55}; // head outside the brain
  case 2: return {0.95, 0.55, 0.60}; // parenchyma
  case 3: return {0.25, 0.55, 1.00}; // ventricles, CSF
  case 4: return {0.30, 0.90, 0.30}; // tumour
  default: {
    const double hue = std::fmod(label * 0.618034, 1.0);
    double rgb[3];
    vtkMath::HSVToRGB(hue, 0.8, 1.0, rgb, rgb + 1, rgb + 2);
    return {rgb[0], rgb[1], rgb[2]};
  }
  }
}

void blend(unsigned char* rgba, const double color[3], double opacity)
{
  for (int c = 0; c < 3; ++c) rgba[c] = (unsigned char)std::lround((1.0 - opacity) * rgba[c] + opacity * 255.0 * color[c]);
  rgba[3] = std::max<unsigned char>(rgba[3], (unsigned char)std::lround(255.0 * opacity));
}

std::array<double, 2> windowLevelOf(const VolumeDisplay& display, const std::array<double, 2>& range)
{
  const double window = display.window.value_or(std::max(range[1] - range[0], 1e-6));
  const double level = display.level.value_or(0.5 * (range[0] + range[1]));
  return {window, level};
}
} // namespace

SliceView::SliceView(SliceOrientation orientation, QWidget* parent)
  : QVTKOpenGLNativeWidget(parent)
  , orientation_(orientation)
  , plane_(planeFor(orientation))
{
  qRegisterMetaType<PhysicalPoint>("brainshift::PhysicalPoint");
  cursor_.Fill(0.0);
  vtkNew<vtkGenericOpenGLRenderWindow> window;
  setRenderWindow(window);
  renderer_ = vtkRenderer::New();
  window->AddRenderer(renderer_);
  renderer_->GetActiveCamera()->ParallelProjectionOn();
  imageActor_ = vtkImageActor::New();
  imageActor_->InterpolateOff();
  imageActor_->VisibilityOff();
  renderer_->AddViewProp(imageActor_);
  crossHair_ = vtkPolyData::New();
  vtkNew<vtkPolyDataMapper> crossHairMapper;
  crossHairMapper->SetInputData(crossHair_);
  crossHairActor_ = vtkActor::New();
  crossHairActor_->SetMapper(crossHairMapper);
  crossHairActor_->GetProperty()->SetColor(1.0, 0.9, 0.2);
  crossHairActor_->VisibilityOff();
  renderer_->AddViewProp(crossHairActor_);
  // The view handles the mouse itself (see the event handlers); VTK's styles would turn the plane.
  vtkNew<vtkInteractorStyleUser> passive;
  interactor()->SetInteractorStyle(passive);
  setMinimumSize(120, 120);
  flicker_ = new QTimer(this);
  flicker_->setInterval(500);
  connect(flicker_, &QTimer::timeout, this, [this] { setFlickerShowsComparison(!flickerShowsComparison_); });
}

SliceView::~SliceView()
{
  renderer_->Delete();
  imageActor_->Delete();
  crossHairActor_->Delete();
  crossHair_->Delete();
}

void SliceView::setBackground(std::shared_ptr<ScalarVolumeNode> node)
{
  // Another volume starts from its own window/level.
  if (node != background_) windowLevelSetHere_ = false;
  background_ = std::move(node);
  updateLayers();
}

void SliceView::setLabelMap(std::shared_ptr<LabelMapVolumeNode> node)
{
  labelMap_ = std::move(node);
  updateLayers();
}

void SliceView::setOverlay(std::shared_ptr<ScalarVolumeNode> node)
{
  overlay_ = std::move(node);
  updateLayers();
}

void SliceView::setComparison(std::shared_ptr<ScalarVolumeNode> node)
{
  comparison_ = std::move(node);
  updateLayers();
}

void SliceView::setComparisonMode(ComparisonMode mode)
{
  comparisonMode_ = mode;
  if (mode == ComparisonMode::Flicker) flicker_->start();
  else flicker_->stop();
  reslice();
  renderWindow()->Render();
}

void SliceView::setCheckerSize(double millimetres)
{
  checkerSize_ = std::max(millimetres, 1e-3);
  reslice();
  renderWindow()->Render();
}

void SliceView::setFlickerShowsComparison(bool showsComparison)
{
  flickerShowsComparison_ = showsComparison;
  reslice();
  renderWindow()->Render();
}

void SliceView::setLabelOutline(bool outline)
{
  labelOutline_ = outline;
  reslice();
  renderWindow()->Render();
}

void SliceView::updateLayers()
{
  const bool hadLayers = !backgroundVolume_.empty() || !labelVolume_.empty() || !overlayVolume_.empty();
  backgroundVolume_ = background_ && background_->image() ? ResliceableVolume(*background_->image()) : ResliceableVolume();
  labelVolume_ = labelMap_ && labelMap_->image() ? ResliceableVolume(*labelMap_->image()) : ResliceableVolume();
  overlayVolume_ = overlay_ && overlay_->image() ? ResliceableVolume(*overlay_->image()) : ResliceableVolume();
  comparisonVolume_ = comparison_ && comparison_->image() ? ResliceableVolume(*comparison_->image()) : ResliceableVolume();
  if (!backgroundVolume_.empty()) {
    backgroundRange_ = backgroundVolume_.scalarRange();
    if (!windowLevelSetHere_) {
      const auto wl = windowLevelOf(background_->display(), backgroundRange_);
      window_ = wl[0];
      level_ = wl[1];
    }
  }
  if (!overlayVolume_.empty()) overlayRange_ = overlayVolume_.scalarRange();
  const auto oldPlane = plane_;
  fitPlaneToLayers();
  const bool hasLayers = !backgroundVolume_.empty() || !labelVolume_.empty() || !overlayVolume_.empty();
  if (hasLayers && !hadLayers) {
    // The first data: the cursor goes to the centre of the reference volume.
    setCursorPosition(plane_.pointAt(plane_.originU + 0.5 * plane_.spacing * (plane_.sizeU - 1),
                                     plane_.originV + 0.5 * plane_.spacing * (plane_.sizeV - 1)));
    plane_.offset = plane_.planeCoordinates(cursor_)[2];
  }
  if (oldPlane.originU != plane_.originU || oldPlane.originV != plane_.originV || oldPlane.sizeU != plane_.sizeU ||
      oldPlane.sizeV != plane_.sizeV || !hadLayers) {
    resetCamera();
  }
  reslice();
  updateCrossHair();
  renderWindow()->Render();
}

void SliceView::fitPlaneToLayers()
{
  const ResliceableVolume* reference = !backgroundVolume_.empty() ? &backgroundVolume_
                                       : !labelVolume_.empty()    ? &labelVolume_
                                       : !overlayVolume_.empty()  ? &overlayVolume_
                                                                  : nullptr;
  if (!reference) return;
  double uMin = 1e300, uMax = -1e300, vMin = 1e300, vMax = -1e300;
  for (const PhysicalPoint& corner : reference->corners()) {
    const Vector3 c = plane_.planeCoordinates(corner);
    uMin = std::min(uMin, c[0]);
    uMax = std::max(uMax, c[0]);
    vMin = std::min(vMin, c[1]);
    vMax = std::max(vMax, c[1]);
  }
  plane_.spacing = reference->smallestSpacing();
  plane_.originU = uMin;
  plane_.originV = vMin;
  plane_.sizeU = std::clamp(int(std::ceil((uMax - uMin) / plane_.spacing)) + 1, 1, 2048);
  plane_.sizeV = std::clamp(int(std::ceil((vMax - vMin) / plane_.spacing)) + 1, 1, 2048);
}

void SliceView::resetCamera()
{
  const double width = plane_.spacing * plane_.sizeU, height = plane_.spacing * plane_.sizeV;
  const double centreU = plane_.originU + 0.5 * plane_.spacing * (plane_.sizeU - 1);
  const double centreV = plane_.originV + 0.5 * plane_.spacing * (plane_.sizeV - 1);
  const double aspect = this->height() > 0 ? double(this->width()) / this->height() : 1.0;
  vtkCamera* camera = renderer_->GetActiveCamera();
  camera->SetFocalPoint(centreU, centreV, 0.0);
  camera->SetPosition(centreU, centreV, 1000.0);
  camera->SetViewUp(0.0, 1.0, 0.0);
  camera->SetParallelScale(0.5 * std::max(height, width / aspect) * 1.02);
  camera->SetClippingRange(1.0, 2000.0);
}

void SliceView::setWindowLevel(double window, double level)
{
  window_ = std::max(window, 1e-6);
  level_ = level;
  windowLevelSetHere_ = true;
  reslice();
  renderWindow()->Render();
}

void SliceView::setLabelOpacity(double opacity)
{
  labelOpacity_ = std::clamp(opacity, 0.0, 1.0);
  reslice();
  renderWindow()->Render();
}

void SliceView::setCursorPosition(const PhysicalPoint& p)
{
  cursor_ = p;
  plane_.offset = plane_.planeCoordinates(p)[2];
  reslice();
  updateCrossHair();
  renderWindow()->Render();
}

namespace {
/// The overlay's colour map over its window: Red (dark red to yellow: angiography), else
/// ColdToHotRainbow (blue through green to red: statistics).
void configureOverlayColors(vtkLookupTable* colors, const VolumeDisplay& display, const std::array<double, 2>& range)
{
  const auto wl = windowLevelOf(display, range);
  if (display.colorTable == "Red") {
    colors->SetHueRange(0.0, 0.17);
    colors->SetValueRange(0.5, 1.0);
  } else {
    colors->SetHueRange(0.667, 0.0);
  }
  colors->SetTableRange(wl[1] - 0.5 * wl[0], wl[1] + 0.5 * wl[0]);
  colors->Build();
}

/// How one slice's pixels are composed, bottom to top: the grey background (or its comparison
/// with another volume), the labels (filled or as outlines), the overlay where shown.
struct SliceCompositor {
  const SlicePlane& plane;
  const float* background;
  const float* labels;
  const float* overlay;
  const float* comparison;
  ComparisonMode comparisonMode;
  double checkerSize;
  bool flickerShowsComparison;
  double window, low;
  double labelOpacity;
  bool labelOutline;
  vtkLookupTable* overlayColors;
  const VolumeDisplay& overlayDisplay;

  /// A label pixel of an outline has a 4-neighbour with another label (or the slice's edge).
  bool onOutline(vtkIdType i) const
  {
    const int u = int(i % plane.sizeU), v = int(i / plane.sizeU);
    const float label = labels[i];
    if (u == 0 || v == 0 || u == plane.sizeU - 1 || v == plane.sizeV - 1) return true;
    return labels[i - 1] != label || labels[i + 1] != label || labels[i - plane.sizeU] != label || labels[i + plane.sizeU] != label;
  }

  /// The background value shown at pixel i in the comparison mode.
  double comparedValue(vtkIdType i, double value) const
  {
    const double other = comparison[i];
    switch (comparisonMode) {
    case ComparisonMode::Checkerboard: {
      const int u = int(i % plane.sizeU), v = int(i / plane.sizeU);
      const long column = long(std::floor((plane.originU + u * plane.spacing) / checkerSize));
      const long row = long(std::floor((plane.originV + v * plane.spacing) / checkerSize));
      if ((column + row) % 2 != 0) value = other;
      break;
    }
    case ComparisonMode::Flicker:
      if (flickerShowsComparison) value = other;
      break;
    case ComparisonMode::Difference:
      value = std::isfinite(value) && std::isfinite(other) ? value - other : std::numeric_limits<double>::quiet_NaN();
      break;
    case ComparisonMode::Off: break;
    }
    return value;
  }

  void compose(vtkIdType i, unsigned char* rgba) const
  {
    rgba[0] = rgba[1] = rgba[2] = rgba[3] = 0;
    double value = background ? background[i] : std::numeric_limits<double>::quiet_NaN();
    double shade = 0.0; // 0..1
    if (comparison) value = comparedValue(i, value);
    if (std::isfinite(value)) {
      shade = comparison && comparisonMode == ComparisonMode::Difference ? 0.5 + value / window : (value - low) / window;
      const auto grey = (unsigned char)std::lround(255.0 * std::clamp(shade, 0.0, 1.0));
      rgba[0] = rgba[1] = rgba[2] = grey;
      rgba[3] = 255;
    }
    if (labels && std::isfinite(labels[i]) && labels[i] > 0.5 && labelOpacity > 0 && (!labelOutline || onOutline(i))) {
      const auto color = labelColor(int(std::lround(labels[i])));
      blend(rgba, color.data(), labelOpacity);
    }
    if (overlay && std::isfinite(overlay[i])) {
      // Shown where lower <= |value| <= upper: a t-map's positive and negative activations alike.
      const double magnitude = std::abs(overlay[i]);
      const bool shown = magnitude >= overlayDisplay.lowerThreshold.value_or(-1e300) &&
                         magnitude <= overlayDisplay.upperThreshold.value_or(1e300);
      if (shown) {
        double color[3];
        overlayColors->GetColor(overlay[i], color);
        blend(rgba, color, overlayDisplay.opacity);
      }
    }
  }
};

const float* scalarsOf(const vtkSmartPointer<vtkImageData>& image)
{
  return image ? static_cast<const float*>(image->GetScalarPointer()) : nullptr;
}
} // namespace

void SliceView::reslice()
{
  if (backgroundVolume_.empty() && labelVolume_.empty() && overlayVolume_.empty()) {
    composed_ = nullptr;
    imageActor_->VisibilityOff();
    return;
  }
  const vtkIdType pixels = vtkIdType(plane_.sizeU) * plane_.sizeV;
  auto valuesOf = [&](const ResliceableVolume& volume) -> vtkSmartPointer<vtkImageData> {
    return volume.empty() ? nullptr : volume.slice(plane_);
  };
  const auto backgroundSlice = valuesOf(backgroundVolume_), labelSlice = valuesOf(labelVolume_), overlaySlice = valuesOf(overlayVolume_);
  const bool comparing = comparisonMode_ != ComparisonMode::Off && !comparisonVolume_.empty() && !backgroundVolume_.empty();
  const auto comparisonSlice = comparing ? comparisonVolume_.slice(plane_) : nullptr;
  const float* overlay = scalarsOf(overlaySlice);
  vtkNew<vtkLookupTable> overlayColors;
  VolumeDisplay overlayDisplay;
  if (overlay) {
    overlayDisplay = overlay_->display();
    configureOverlayColors(overlayColors, overlayDisplay, overlayRange_);
  }
  const double labelOpacity = labelMap_ ? labelOpacity_ * labelMap_->display().opacity : 0.0;
  const SliceCompositor compositor{plane_, scalarsOf(backgroundSlice), scalarsOf(labelSlice), overlay, scalarsOf(comparisonSlice),
                                  comparisonMode_, checkerSize_, flickerShowsComparison_, window_, level_ - 0.5 * window_,
                                  labelOpacity, labelOutline_, overlayColors, overlayDisplay};
  auto composed = vtkSmartPointer<vtkImageData>::New();
  composed->SetDimensions(plane_.sizeU, plane_.sizeV, 1);
  composed->SetOrigin(plane_.originU, plane_.originV, 0.0);
  composed->SetSpacing(plane_.spacing, plane_.spacing, 1.0);
  composed->AllocateScalars(VTK_UNSIGNED_CHAR, 4);
  auto* rgba = static_cast<unsigned char*>(composed->GetScalarPointer());
  for (vtkIdType i = 0; i < pixels; ++i, rgba += 4) compositor.compose(i, rgba);
  composed_ = composed;
  imageActor_->SetInputData(composed_);
  imageActor_->VisibilityOn();
}

void SliceView::updateCrossHair()
{
  if (!composed_) {
    crossHairActor_->VisibilityOff();
    return;
  }
  const Vector3 c = plane_.planeCoordinates(cursor_);
  const double u0 = plane_.originU, u1 = plane_.originU + plane_.spacing * (plane_.sizeU - 1);
  const double v0 = plane_.originV, v1 = plane_.originV + plane_.spacing * (plane_.sizeV - 1);
  vtkNew<vtkPoints> points;
  points->InsertNextPoint(u0, c[1], 1.0);
  points->InsertNextPoint(u1, c[1], 1.0);
  points->InsertNextPoint(c[0], v0, 1.0);
  points->InsertNextPoint(c[0], v1, 1.0);
  vtkNew<vtkCellArray> lines;
  const vtkIdType horizontal[2] = {0, 1}, vertical[2] = {2, 3};
  lines->InsertNextCell(2, horizontal);
  lines->InsertNextCell(2, vertical);
  crossHair_->SetPoints(points);
  crossHair_->SetLines(lines);
  crossHair_->Modified();
  crossHairActor_->VisibilityOn();
}

PhysicalPoint SliceView::pointAtPixel(const QPoint& pixel) const
{
  const double ratio = devicePixelRatioF();
  renderer_->SetDisplayPoint(pixel.x() * ratio, (height() - 1 - pixel.y()) * ratio, 0.0);
  renderer_->DisplayToWorld();
  double world[4];
  renderer_->GetWorldPoint(world);
  if (world[3] != 0.0) {
    for (int i = 0; i < 3; ++i) world[i] /= world[3];
  }
  return plane_.pointAt(world[0], world[1]);
}

std::optional<std::array<unsigned char, 4>> SliceView::colorAt(const PhysicalPoint& p) const
{
  if (!composed_) return std::nullopt;
  const Vector3 c = plane_.planeCoordinates(p);
  if (std::abs(c[2] - plane_.offset) > 0.5 * plane_.spacing) return std::nullopt;
  const long i = std::lround((c[0] - plane_.originU) / plane_.spacing), j = std::lround((c[1] - plane_.originV) / plane_.spacing);
  if (i < 0 || j < 0 || i >= plane_.sizeU || j >= plane_.sizeV) return std::nullopt;
  const auto* rgba = static_cast<const unsigned char*>(composed_->GetScalarPointer(int(i), int(j), 0));
  return std::array<unsigned char, 4>{rgba[0], rgba[1], rgba[2], rgba[3]};
}

void SliceView::mousePressEvent(QMouseEvent* event)
{
  if (event->button() == Qt::LeftButton && composed_) {
    const PhysicalPoint p = pointAtPixel(event->pos());
    setCursorPosition(p);
    emit cursorPicked(p);
  } else if (event->button() == Qt::RightButton) {
    dragStart_ = event->pos();
    dragStartWindowLevel_ = {window_, level_};
  }
}

void SliceView::mouseMoveEvent(QMouseEvent* event)
{
  if ((event->buttons() & Qt::LeftButton) && composed_) {
    const PhysicalPoint p = pointAtPixel(event->pos());
    setCursorPosition(p);
    emit cursorPicked(p);
  } else if ((event->buttons() & Qt::RightButton) && !backgroundVolume_.empty()) {
    // Right and left widen and narrow the window, down and up lower and raise the level.
    const double scale = std::max(backgroundRange_[1] - backgroundRange_[0], 1e-6) / std::max(width(), 1);
    const QPoint delta = event->pos() - dragStart_;
    setWindowLevel(dragStartWindowLevel_[0] + delta.x() * scale, dragStartWindowLevel_[1] - delta.y() * scale);
  }
}

void SliceView::wheelEvent(QWheelEvent* event)
{
  if (!composed_) return;
  const double steps = event->angleDelta().y() / 120.0;
  PhysicalPoint p = cursor_;
  for (int i = 0; i < 3; ++i) p[i] += steps * plane_.spacing * plane_.normal[i];
  setCursorPosition(p);
  emit cursorPicked(p);
}

} // namespace brainshift
