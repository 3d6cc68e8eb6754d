#include "ImageTypes.h"

#include <cmath>
#include <sstream>

namespace brainshift {

bool ImageGeometry::sameGridAs(const ImageGeometry& other, double tolerance) const
{
  for (unsigned i = 0; i < Dimension; ++i) {
    if (size[i] != other.size[i]) return false;
    if (std::abs(spacing[i] - other.spacing[i]) > tolerance * spacing[i]) return false;
    if (std::abs(origin[i] - other.origin[i]) > tolerance * spacing[i] * 10) return false;
    for (unsigned j = 0; j < Dimension; ++j) {
      if (std::abs(direction(i, j) - other.direction(i, j)) > tolerance) return false;
    }
  }
  return true;
}

std::string ImageGeometry::describe() const
{
  std::ostringstream s;
  s << size[0] << "x" << size[1] << "x" << size[2] << " voxels of " << spacing[0] << "x"
    << spacing[1] << "x" << spacing[2] << " mm, origin (" << origin[0] << ", " << origin[1]
    << ", " << origin[2] << ")";
  return s.str();
}

} // namespace brainshift
