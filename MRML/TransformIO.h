#pragma once
// ITK transform files: .tfm/.txt (text), .mat (Matlab), .h5 (HDF5, composite transforms
// included), and displacement fields stored as vector images (.nrrd, .nii.gz, .mha) with the
// convention x = y + d(y). Every transform here is a resampling transform: it maps a point of the
// fixed (for BrainShift: intraoperative) space to the moving (preoperative) space.
#include "BrainShiftErrors.h"
#include "ImageTypes.h"

#include <itkTransform.h>

#include <filesystem>

namespace brainshift {

using SpatialTransform = itk::Transform<double, 3, 3>;

/// Reads one transform. A file that holds a composite gives the composite; a displacement-field
/// image gives an itk::DisplacementFieldTransform. InputError naming the file otherwise.
SpatialTransform::Pointer readTransform(const std::filesystem::path& path);

/// Writes atomically. A composite needs .h5; a displacement field transform may also be written
/// as a vector image (.nrrd, .nii.gz) when its field is what is wanted.
void writeTransform(const SpatialTransform* transform, const std::filesystem::path& path);

/// True if the transform is affine (a 4x4 matrix describes it: Euler, versor, similarity, affine).
bool isLinearTransform(const SpatialTransform* transform);

/// The 3x3 matrix and translation of a linear transform, LPS, y -> A y + t.
struct AffineParameters {
  double matrix[3][3];
  double translation[3];
};
AffineParameters affineParametersOf(const SpatialTransform* transform);

/// A displacement field transform (x = y + d(y)) over the field's grid; zero outside it.
SpatialTransform::Pointer makeDisplacementFieldTransform(DisplacementFieldImage* field);

/// A field of doubles, the type ITK's composite transforms hold.
using DoubleDisplacementFieldImage = itk::Image<itk::Vector<double, 3>, 3>;
/// The same over a field of doubles, taken as it is (no copy): for a field made in doubles.
SpatialTransform::Pointer makeDisplacementFieldTransform(DoubleDisplacementFieldImage* field);

/// The field of a displacement field transform, or null if `transform` is not one.
DisplacementFieldImage::Pointer displacementFieldOf(const SpatialTransform* transform);

/// "Euler3DTransform", "CompositeTransform (2 transforms)", ...
std::string describeTransform(const SpatialTransform* transform);

} // namespace brainshift
