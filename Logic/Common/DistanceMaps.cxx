#include "DistanceMaps.h"

#include <itkSignedMaurerDistanceMapImageFilter.h>

namespace brainshift {

ScalarImage::Pointer signedDistanceMm(const MaskImage* mask)
{
  auto distance = itk::SignedMaurerDistanceMapImageFilter<MaskImage, ScalarImage>::New();
  distance->SetInput(mask);
  distance->SetUseImageSpacing(true);
  distance->SetSquaredDistance(false);
  distance->SetInsideIsPositive(false);
  distance->SetBackgroundValue(0);
  distance->Update();
  ScalarImage::Pointer out = distance->GetOutput();
  out->DisconnectPipeline();
  return out;
}

} // namespace brainshift
