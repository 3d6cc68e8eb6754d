#include "OrientationPhantom.h"

#include <itkCastImageFilter.h>
#include <itkGDCMImageIO.h>
#include <itkImageRegionIteratorWithIndex.h>
#include <itkImageSeriesWriter.h>
#include <itkMetaDataObject.h>

#include <iomanip>
#include <sstream>

namespace brainshift::testing {
namespace fs = std::filesystem;

OrientationPhantom makeOrientationPhantom(const ScalarImage::SizeType& size, const ScalarImage::SpacingType& spacing,
                                          const ScalarImage::DirectionType& direction, const PhysicalPoint& centre)
{
  OrientationPhantom phantom;
  phantom.image = ScalarImage::New();
  ScalarImage::RegionType region;
  region.SetSize(size);
  phantom.image->SetRegions(region);
  phantom.image->SetSpacing(spacing);
  phantom.image->SetDirection(direction);
  // The origin that puts the grid's centre at `centre`.
  ScalarImage::PointType origin;
  for (unsigned r = 0; r < 3; ++r) {
    double offset = 0;
    for (unsigned c = 0; c < 3; ++c) offset += direction(r, c) * spacing[c] * (size[c] - 1) / 2.0;
    origin[r] = centre[r] - offset;
  }
  phantom.image->SetOrigin(origin);
  phantom.image->Allocate();
  phantom.image->FillBuffer(10.0f);

  phantom.left = centre;
  phantom.left[0] += 25;
  phantom.anterior = centre;
  phantom.anterior[1] -= 20;
  phantom.superior = centre;
  phantom.superior[2] += 15;
  const std::pair<PhysicalPoint, float> spheres[] = {{phantom.left, 300.f}, {phantom.anterior, 200.f}, {phantom.superior, 100.f}};

  itk::ImageRegionIteratorWithIndex<ScalarImage> it(phantom.image, region);
  for (; !it.IsAtEnd(); ++it) {
    PhysicalPoint p;
    phantom.image->TransformIndexToPhysicalPoint(it.GetIndex(), p);
    for (const auto& [c, value] : spheres) {
      if (p.EuclideanDistanceTo(c) <= 6.0) it.Set(value);
    }
  }
  return phantom;
}

PhysicalPoint centroidOfValue(const ScalarImage* image, float value)
{
  double sum[3] = {0, 0, 0};
  std::size_t count = 0;
  itk::ImageRegionConstIteratorWithIndex<ScalarImage> it(image, image->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    if (std::abs(it.Get() - value) <= 0.5f) {
      PhysicalPoint p;
      image->TransformIndexToPhysicalPoint(it.GetIndex(), p);
      for (int i = 0; i < 3; ++i) sum[i] += p[i];
      ++count;
    }
  }
  PhysicalPoint centroid;
  for (int i = 0; i < 3; ++i) centroid[i] = count ? sum[i] / count : std::nan("");
  return centroid;
}

void writeDicomSeries(const ScalarImage* image, const fs::path& folder, int skipSlice)
{
  using ShortImage = itk::Image<short, 3>;
  using SliceImage = itk::Image<short, 2>;
  fs::create_directories(folder);
  auto cast = itk::CastImageFilter<ScalarImage, ShortImage>::New();
  cast->SetInput(image);
  cast->Update();

  auto io = itk::GDCMImageIO::New();
  io->KeepOriginalUIDOn();
  auto& dictionary = io->GetMetaDataDictionary();
  // One study and one series for all slices; the writer adds each slice's position.
  itk::EncapsulateMetaData<std::string>(dictionary, "0020|000d", "1.2.826.0.1.3680043.2.1125.1.1");
  itk::EncapsulateMetaData<std::string>(dictionary, "0020|000e", "1.2.826.0.1.3680043.2.1125.1.2");
  itk::EncapsulateMetaData<std::string>(dictionary, "0008|0060", "MR");
  itk::EncapsulateMetaData<std::string>(dictionary, "0008|0016", "1.2.840.10008.5.1.4.1.1.4");
  itk::EncapsulateMetaData<std::string>(dictionary, "0028|0004", "MONOCHROME2"); // else GDCM warns per slice

  const unsigned slices = image->GetLargestPossibleRegion().GetSize()[2];
  std::vector<std::string> names;
  for (unsigned k = 0; k < slices; ++k) {
    std::ostringstream name;
    name << "slice" << std::setw(4) << std::setfill('0') << k << ".dcm";
    names.push_back((folder / name.str()).string());
  }
  auto writer = itk::ImageSeriesWriter<ShortImage, SliceImage>::New();
  writer->SetInput(cast->GetOutput());
  writer->SetImageIO(io);
  writer->SetFileNames(names);
  writer->Update();
  if (skipSlice >= 0 && skipSlice < static_cast<int>(slices)) {
    fs::remove(names[skipSlice]);
  }
}

} // namespace brainshift::testing
