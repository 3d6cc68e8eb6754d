#pragma once
// Distance maps of binary masks, shared by the stages (ITK's Maurer transform stays in the .cxx).
#include "ImageTypes.h"

#include <array>
#include <vector>

namespace brainshift {

/// The signed Euclidean distance (mm, using the spacing) from every voxel to the boundary of the
/// mask's non-zero region: negative inside, positive outside.
ScalarImage::Pointer signedDistanceMm(const MaskImage* mask);

/// The signed distance (mm) to the faces between the mask's voxels and the others: negative
/// inside. ITK's signed Maurer distance puts its zero level on the centres of the mask's own
/// boundary voxels, half a voxel inside; this averages it with the distance of the complement so
/// that the zero level lies on the voxel faces, where the boundary is (matters on thick slices).
ScalarImage::Pointer boundaryDistanceMm(const MaskImage* mask);

/// The voxels at least `depthMm` inside the mask: signedDistanceMm(mask) <= -depthMm, found without
/// a distance map (a voxel is that deep when no boundary voxel of the mask, one with a voxel of the
/// complement among its 26 neighbours, lies nearer than depthMm). Cheap for masks far smaller than
/// their grid, and for small depths. A mask touching the grid's edge: ITK sees no boundary there,
/// this sees one (the outside counts as complement).
MaskImage::Pointer voxelsAtLeastDeep(const MaskImage* mask, double depthMm);

/// The offsets voxelsAtLeastDeep tests about a mask voxel on `spacing`: the voxel is at least
/// `depthMm` deep exactly when every one of them is in the mask (the open ball of that radius,
/// grown by one voxel: a complement voxel in it makes the path towards the centre cross a boundary
/// voxel). For callers that test a few voxels, not the whole mask (block matching's centres).
std::vector<std::array<long, 3>> depthTestOffsets(const MaskImage::SpacingType& spacing, double depthMm);

/// The voxels within `reachMm` of the mask: signedDistanceMm(mask) <= reachMm (the mask itself and
/// the complement's voxels that close to a mask voxel), found without a distance map.
MaskImage::Pointer voxelsWithin(const MaskImage* mask, double reachMm);

} // namespace brainshift
