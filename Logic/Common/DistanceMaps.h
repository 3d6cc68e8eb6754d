#pragma once
// Distance maps of binary masks, shared by the stages (ITK's Maurer transform stays in the .cxx).
#include "ImageTypes.h"

namespace brainshift {

using MaskImage = itk::Image<unsigned char, 3>;

/// The signed Euclidean distance (mm, using the spacing) from every voxel to the boundary of the
/// mask's non-zero region: negative inside, positive outside.
ScalarImage::Pointer signedDistanceMm(const MaskImage* mask);

} // namespace brainshift
