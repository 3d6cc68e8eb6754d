#include "ViewLayout.h"

#include <QGridLayout>
#include <QLabel>
#include <QVBoxLayout>

#include <algorithm>

namespace brainshift {

ViewLayout::ViewLayout(QWidget* parent)
  : QWidget(parent)
{
  cursor_.Fill(0.0);
  auto* column = new QVBoxLayout(this);
  column->setContentsMargins(0, 0, 0, 0);
  grid_ = new QGridLayout;
  grid_->setSpacing(2);
  column->addLayout(grid_, 1);
  readout_ = new QLabel(this);
  readout_->setObjectName("cursorReadout");
  readout_->setTextInteractionFlags(Qt::TextSelectableByMouse);
  column->addWidget(readout_);

  slices_ = {new SliceView(SliceOrientation::Axial, this), new SliceView(SliceOrientation::Sagittal, this),
             new SliceView(SliceOrientation::Coronal, this)};
  threeD_ = new ThreeDView(this);
  for (SliceView* view : slices_) {
    view->setObjectName(toString(view->orientation()) + "SliceView");
    connect(view, &SliceView::cursorPicked, this, [this](const PhysicalPoint& p) {
      setCursorPosition(p);
      emit pointPicked(p);
    });
  }
  threeD_->setObjectName("ThreeDView");
  // Four-up: axial and 3D on top, coronal and sagittal below (Slicer's conventional layout).
  grid_->addWidget(slices_[0], 0, 0);
  grid_->addWidget(threeD_, 0, 1);
  grid_->addWidget(slices_[2], 1, 0);
  grid_->addWidget(slices_[1], 1, 1);
  updateReadout();
}

SliceView* ViewLayout::sliceView(SliceOrientation orientation) const
{
  return slices_[int(orientation)];
}

void ViewLayout::setArrangement(ViewArrangement arrangement)
{
  arrangement_ = arrangement;
  const bool fourUp = arrangement == ViewArrangement::FourUp;
  slices_[0]->setVisible(fourUp || arrangement == ViewArrangement::OneUpAxial);
  slices_[1]->setVisible(fourUp || arrangement == ViewArrangement::OneUpSagittal);
  slices_[2]->setVisible(fourUp || arrangement == ViewArrangement::OneUpCoronal);
  threeD_->setVisible(fourUp || arrangement == ViewArrangement::OneUp3D);
}

void ViewLayout::setBackground(std::shared_ptr<ScalarVolumeNode> node)
{
  for (SliceView* view : slices_) view->setBackground(node);
  setCursorPosition(slices_[0]->cursorPosition());
}

void ViewLayout::setLabelMap(std::shared_ptr<LabelMapVolumeNode> node)
{
  for (SliceView* view : slices_) view->setLabelMap(node);
  setCursorPosition(slices_[0]->cursorPosition());
}

void ViewLayout::setOverlay(std::shared_ptr<ScalarVolumeNode> node)
{
  for (SliceView* view : slices_) view->setOverlay(node);
  setCursorPosition(slices_[0]->cursorPosition());
}

void ViewLayout::setComparison(std::shared_ptr<ScalarVolumeNode> node)
{
  for (SliceView* view : slices_) view->setComparison(node);
  updateReadout();
}

void ViewLayout::setComparisonMode(ComparisonMode mode)
{
  for (SliceView* view : slices_) view->setComparisonMode(mode);
  updateReadout();
}

void ViewLayout::setLabelOutline(bool outline)
{
  for (SliceView* view : slices_) view->setLabelOutline(outline);
}

void ViewLayout::updateLayers()
{
  for (SliceView* view : slices_) view->updateLayers();
  updateReadout();
}

void ViewLayout::setCursorPosition(const PhysicalPoint& p)
{
  cursor_ = p;
  for (SliceView* view : slices_) {
    if (view->cursorPosition() != p) view->setCursorPosition(p);
  }
  updateReadout();
  updateSlicePlanes();
  emit cursorMoved(p);
}

void ViewLayout::updateSlicePlanes()
{
  const auto& background = slices_[0]->background();
  if (!background || !background->image()) return;
  // The background's extent in LPS mm: the box of its corner voxels' centres.
  const ScalarImage& image = *background->image();
  const auto size = image.GetLargestPossibleRegion().GetSize();
  std::array<double, 6> bounds{1e300, -1e300, 1e300, -1e300, 1e300, -1e300};
  for (int corner = 0; corner < 8; ++corner) {
    ScalarImage::IndexType index;
    for (unsigned d = 0; d < 3; ++d) index[d] = (corner >> d) & 1 ? long(size[d]) - 1 : 0;
    PhysicalPoint x;
    image.TransformIndexToPhysicalPoint(index, x);
    for (unsigned d = 0; d < 3; ++d) {
      bounds[2 * d] = std::min(bounds[2 * d], x[d]);
      bounds[2 * d + 1] = std::max(bounds[2 * d + 1], x[d]);
    }
  }
  threeD_->setSlicePlanes(cursor_, bounds);
}

std::vector<LayerValue> ViewLayout::valuesAtCursor() const
{
  std::vector<LayerValue> values;
  const SliceView* view = slices_[0];
  if (const auto& node = view->background(); node && node->image()) {
    values.push_back({QString::fromStdString(node->name()), intensityAt(*node->image(), cursor_)});
  }
  if (const auto& node = view->labelMap(); node && node->image()) {
    const auto label = labelAt(*node->image(), cursor_);
    values.push_back({QString::fromStdString(node->name()), label ? std::optional<double>(*label) : std::nullopt});
  }
  if (const auto& node = view->overlay(); node && node->image()) {
    values.push_back({QString::fromStdString(node->name()), intensityAt(*node->image(), cursor_)});
  }
  if (const auto& node = view->comparison(); node && node->image() && view->comparisonMode() != ComparisonMode::Off) {
    values.push_back({QString::fromStdString(node->name()), intensityAt(*node->image(), cursor_)});
  }
  return values;
}

QString ViewLayout::readoutText() const
{
  return readout_->text();
}

void ViewLayout::updateReadout()
{
  readout_->setText(formatReadout(cursor_, valuesAtCursor()));
}

} // namespace brainshift
