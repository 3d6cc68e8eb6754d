#pragma once
// A left/right-asymmetric phantom for orientation tests: three spheres of distinct values at known
// LPS points (patient left, anterior, superior of the centre), so that any flip or swap of axes
// through a reader or writer moves a sphere away from where it belongs.
#include "ImageTypes.h"

#include <filesystem>

namespace brainshift::testing {

struct OrientationPhantom {
  ScalarImage::Pointer image;
  PhysicalPoint left;     ///< value 300: 25 mm towards the patient's left (+x in LPS)
  PhysicalPoint anterior; ///< value 200: 20 mm anterior (-y in LPS)
  PhysicalPoint superior; ///< value 100: 15 mm superior (+z in LPS)
};

/// The phantom on a grid of `size` voxels with the given spacing and direction, centred at
/// `centre` (LPS mm). The spheres have a 6 mm radius.
OrientationPhantom makeOrientationPhantom(const ScalarImage::SizeType& size, const ScalarImage::SpacingType& spacing,
                                          const ScalarImage::DirectionType& direction, const PhysicalPoint& centre);

/// The physical centroid of the voxels whose value is `value` (+-0.5).
PhysicalPoint centroidOfValue(const ScalarImage* image, float value);

/// Writes `image` as a DICOM MR series (int16), one file per slice along the third axis.
/// `skipSlice` >= 0 leaves that slice out (a series with a missing slice).
void writeDicomSeries(const ScalarImage* image, const std::filesystem::path& folder, int skipSlice = -1);

} // namespace brainshift::testing
