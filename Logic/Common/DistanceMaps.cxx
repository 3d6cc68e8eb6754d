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

ScalarImage::Pointer boundaryDistanceMm(const MaskImage* mask)
{
  auto complement = MaskImage::New();
  complement->SetRegions(mask->GetLargestPossibleRegion());
  complement->CopyInformation(mask);
  complement->Allocate();
  const unsigned char* m = mask->GetBufferPointer();
  unsigned char* c = complement->GetBufferPointer();
  const std::size_t n = mask->GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) c[i] = m[i] ? 0 : 1;
  ScalarImage::Pointer inside = signedDistanceMm(mask);
  const ScalarImage::Pointer outside = signedDistanceMm(complement);
  float* a = inside->GetBufferPointer();
  const float* b = outside->GetBufferPointer();
  for (std::size_t i = 0; i < n; ++i) a[i] = 0.5f * (a[i] - b[i]);
  return inside;
}

} // namespace brainshift
