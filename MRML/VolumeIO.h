#pragma once
// Reading and writing volumes: NIfTI (.nii, .nii.gz), NRRD (.nrrd, .nhdr), MetaImage (.mha,
// .mhd) and DICOM series (a folder). Physical space is LPS mm, as ITK reads it; NIfTI's RAS
// sform/qform is converted by ITK. Every failure is an InputError naming the file.
#include "BrainShiftErrors.h"
#include "ImageTypes.h"

#include <filesystem>

namespace brainshift {

/// How the voxels are stored on disk by the writers (intensities are float in memory).
enum class StoredPixelType { Float32, Int16, UInt8 };

/// A 3D single-component image, converted to float. A folder is read as one DICOM series.
/// Refuses non-finite voxels, vector images and 2D or 4D images. Warns (NIfTI) when qform
/// and sform are both set and disagree.
ScalarImage::Pointer readScalarVolume(const std::filesystem::path& path, Warnings* warnings = nullptr);

/// A label map: a 3D image of non-negative integer values up to 65535.
LabelImage::Pointer readLabelVolume(const std::filesystem::path& path, Warnings* warnings = nullptr);

/// A 3-component vector image of displacements in LPS mm (x = y + d(y)).
DisplacementFieldImage::Pointer readDisplacementField(const std::filesystem::path& path);

/// One DICOM series from a folder (ITK GDCM). The slice spacing is taken from the image
/// positions; a series with missing slices, uneven spacing, mixed orientations or several
/// series in the folder is refused.
ScalarImage::Pointer readDicomSeries(const std::filesystem::path& folder, Warnings* warnings = nullptr);

/// Writers choose the format by extension and write atomically (compressed where the format
/// allows). Int16/UInt8 round and clamp.
void writeScalarVolume(const ScalarImage* image, const std::filesystem::path& path,
                       StoredPixelType stored = StoredPixelType::Float32);
void writeLabelVolume(const LabelImage* image, const std::filesystem::path& path);
void writeDisplacementField(const DisplacementFieldImage* field, const std::filesystem::path& path);

/// True when `path` names a format the volume readers accept (by extension), or is a folder.
bool isVolumePath(const std::filesystem::path& path);

/// Registers ITK's image and transform IO factories once (no ITK_USE_FILE needed).
void registerIOFactories();

} // namespace brainshift
