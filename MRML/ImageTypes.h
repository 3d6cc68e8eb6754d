#pragma once
// The image types of the scene. Intensities are float whatever the file holds; label maps are
// unsigned 16-bit (the contract's labels 0-4, and room for labels a configuration adds).
#include <itkImage.h>
#include <itkVector.h>

#include <string>

namespace brainshift {

constexpr unsigned int Dimension = 3;
using ScalarImage = itk::Image<float, Dimension>;
using LabelPixel = unsigned short;
using LabelImage = itk::Image<LabelPixel, Dimension>;
/// A binary mask: 1 in, 0 out.
using MaskImage = itk::Image<unsigned char, Dimension>;
/// A displacement field in LPS mm: the mapping x = y + d(y).
using DisplacementVector = itk::Vector<float, Dimension>;
using DisplacementFieldImage = itk::Image<DisplacementVector, Dimension>;
using PhysicalPoint = itk::Point<double, Dimension>;

/// The grid of an image: size, spacing, origin, direction (LPS).
struct ImageGeometry {
  ScalarImage::SizeType size{};
  ScalarImage::SpacingType spacing;
  ScalarImage::PointType origin;
  ScalarImage::DirectionType direction;

  template <class TImage>
  static ImageGeometry of(const TImage* image)
  {
    ImageGeometry g;
    g.size = image->GetLargestPossibleRegion().GetSize();
    g.spacing = image->GetSpacing();
    g.origin = image->GetOrigin();
    g.direction = image->GetDirection();
    return g;
  }

  /// Same grid within `tolerance` (relative to the spacing for origins, absolute for directions).
  bool sameGridAs(const ImageGeometry& other, double tolerance = 1e-4) const;
  /// "181x217x181 voxels of 1x1x1 mm, origin (90, 125, -71)".
  std::string describe() const;
  std::size_t numberOfVoxels() const { return size[0] * size[1] * size[2]; }

  /// An allocated, uninitialised image of any pixel type on this grid.
  template <class TImage>
  typename TImage::Pointer allocate() const
  {
    auto image = TImage::New();
    typename TImage::RegionType region;
    region.SetSize(size);
    image->SetRegions(region);
    image->SetSpacing(spacing);
    image->SetOrigin(origin);
    image->SetDirection(direction);
    image->Allocate();
    return image;
  }
};

} // namespace brainshift
