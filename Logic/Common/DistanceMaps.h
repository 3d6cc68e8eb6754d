#pragma once
// Distance maps of binary masks, shared by the stages (ITK's Maurer transform stays in the .cxx).
#include "ImageTypes.h"

namespace brainshift {

using MaskImage = itk::Image<unsigned char, 3>;

/// The signed Euclidean distance (mm, using the spacing) from every voxel to the boundary of the
/// mask's non-zero region: negative inside, positive outside.
ScalarImage::Pointer signedDistanceMm(const MaskImage* mask);

/// The signed distance (mm) to the faces between the mask's voxels and the others: negative
/// inside. ITK's signed Maurer distance puts its zero level on the centres of the mask's own
/// boundary voxels, half a voxel inside; this averages it with the distance of the complement so
/// that the zero level lies on the voxel faces, where the boundary is (matters on thick slices).
ScalarImage::Pointer boundaryDistanceMm(const MaskImage* mask);

} // namespace brainshift
