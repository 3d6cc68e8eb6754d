#include "LayerReadout.h"

#include <itkLinearInterpolateImageFunction.h>

namespace brainshift {

std::optional<double> intensityAt(const ScalarImage& image, const PhysicalPoint& p)
{
  using Interpolator = itk::LinearInterpolateImageFunction<ScalarImage, double>;
  auto interpolator = Interpolator::New();
  interpolator->SetInputImage(&image);
  Interpolator::ContinuousIndexType index;
  image.TransformPhysicalPointToContinuousIndex(p, index);
  if (!interpolator->IsInsideBuffer(index)) return std::nullopt;
  return interpolator->EvaluateAtContinuousIndex(index);
}

std::optional<LabelPixel> labelAt(const LabelImage& image, const PhysicalPoint& p)
{
  LabelImage::IndexType index;
  if (!image.TransformPhysicalPointToIndex(p, index)) return std::nullopt;
  return image.GetPixel(index);
}

QString formatReadout(const PhysicalPoint& p, const std::vector<LayerValue>& values)
{
  QString text = QString("LPS (%1, %2, %3) mm").arg(p[0], 0, 'f', 1).arg(p[1], 0, 'f', 1).arg(p[2], 0, 'f', 1);
  for (const LayerValue& v : values) {
    text += QString(" | %1 %2").arg(v.layer, v.value ? QString::number(*v.value, 'g', 5) : QString("outside"));
  }
  return text;
}

} // namespace brainshift
