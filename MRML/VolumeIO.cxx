#include "VolumeIO.h"

#include "AtomicItkWrite.h"
#include "LibraryMessages.h"
#include "FileNames.h"

#include <itkCastImageFilter.h>
#include <itkGDCMImageIO.h>
#include <itkGDCMImageIOFactory.h>
#include <itkGDCMSeriesFileNames.h>
#include <itkHDF5TransformIOFactory.h>
#include <itkImageFileReader.h>
#include <itkImageFileWriter.h>
#include <itkImageIOFactory.h>
#include <itkImageRegionConstIterator.h>
#include <itkImageSeriesReader.h>
#include <itkMatlabTransformIOFactory.h>
#include <itkMetaImageIOFactory.h>
#include <itkNiftiImageIOFactory.h>
#include <itkNrrdImageIOFactory.h>
#include <itkTransformFactoryBase.h>
#include <itkTxtTransformIOFactory.h>

#include <zlib.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <sstream>
#include <vector>

namespace brainshift {
namespace fs = std::filesystem;

void registerIOFactories()
{
  static std::once_flag once;
  std::call_once(once, [] {
    itk::NiftiImageIOFactory::RegisterOneFactory();
    itk::NrrdImageIOFactory::RegisterOneFactory();
    itk::MetaImageIOFactory::RegisterOneFactory();
    itk::GDCMImageIOFactory::RegisterOneFactory();
    itk::HDF5TransformIOFactory::RegisterOneFactory();
    itk::TxtTransformIOFactory::RegisterOneFactory();
    itk::MatlabTransformIOFactory::RegisterOneFactory();
    itk::TransformFactoryBase::RegisterDefaultTransforms();
  });
}

namespace {

bool isNiftiFile(const fs::path& path)
{
  return hasExtension(path, {".nii", ".nii.gz"});
}

void requireExistingFile(const fs::path& path)
{
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    throw InputError(path.string() + ": no such file");
  }
  if (fs::is_regular_file(path, ec) && fs::file_size(path, ec) == 0) {
    throw InputError(path.string() + ": the file is empty");
  }
}

/// Opens the header of `path` and checks it is a 3D image with `components` components.
itk::ImageIOBase::Pointer readImageHeader(const fs::path& path, unsigned components)
{
  registerIOFactories();
  requireExistingFile(path);
  // niftilib prints its own "** ERROR: ..." lines for a bad header and carries on; ITK's exception
  // (or a null IO) is reported instead, once.
  MutedStderr quiet;
  itk::ImageIOBase::Pointer io =
    itk::ImageIOFactory::CreateImageIO(path.c_str(), itk::ImageIOFactory::IOFileModeEnum::ReadMode);
  if (!io) {
    throw InputError(path.string() +
                     ": not an image file that can be read (expected NIfTI, NRRD, MetaImage or a DICOM folder)");
  }
  try {
    io->SetFileName(path.string());
    io->ReadImageInformation();
  } catch (const itk::ExceptionObject& e) {
    throw InputError(path.string() + ": cannot read the image header: " + oneLine(e.GetDescription()));
  }
  unsigned dimensions = io->GetNumberOfDimensions();
  // A 4D file with a single volume is a 3D image.
  while (dimensions > 3 && io->GetDimensions(dimensions - 1) == 1) {
    --dimensions;
  }
  if (dimensions != 3) {
    throw InputError(path.string() + ": a " + std::to_string(dimensions) +
                     "D image; a 3D volume is expected");
  }
  if (io->GetNumberOfComponents() != components) {
    throw InputError(path.string() + ": " + std::to_string(io->GetNumberOfComponents()) +
                     " components per voxel; " + std::to_string(components) + " expected");
  }
  for (unsigned i = 0; i < 3; ++i) {
    if (io->GetDimensions(i) < 1 || !(io->GetSpacing(i) > 0) || !std::isfinite(io->GetSpacing(i))) {
      throw InputError(path.string() + ": invalid size or spacing along axis " + std::to_string(i));
    }
    // A medical image's voxels are micrometres to centimetres; its origin within a few metres.
    if (io->GetSpacing(i) < 1e-3 || io->GetSpacing(i) > 1e3 || !(std::abs(io->GetOrigin(i)) <= 1e5)) {
      std::ostringstream message;
      message << path.string() << ": a voxel size of " << io->GetSpacing(i) << " mm and an origin at " << io->GetOrigin(i)
              << " mm along axis " << i << " are not those of a medical image (voxels of 0.001 to 1000 mm, origin within 100 m)";
      throw InputError(message.str());
    }
  }
  return io;
}

template <class TImage>
typename TImage::Pointer readImageFile(const fs::path& path)
{
  auto reader = itk::ImageFileReader<TImage>::New();
  reader->SetFileName(path.string());
  MutedStderr quiet; // niftilib's own "** ERROR" lines; the exception says it once
  try {
    reader->Update();
  } catch (const itk::ExceptionObject& e) {
    throw InputError(path.string() + ": cannot read the image (truncated or corrupt?): " + oneLine(e.GetDescription()));
  }
  typename TImage::Pointer image = reader->GetOutput();
  image->DisconnectPipeline();
  return image;
}

void requireFinite(const ScalarImage* image, const fs::path& path)
{
  std::size_t bad = 0;
  itk::ImageRegionConstIterator<ScalarImage> it(image, image->GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    if (!std::isfinite(it.Get())) ++bad;
  }
  if (bad > 0) {
    throw InputError(path.string() + ": " + std::to_string(bad) + " voxels are NaN or infinite");
  }
}

// ---- NIfTI qform/sform agreement --------------------------------------------------------
struct NiftiTransforms {
  short qformCode = 0, sformCode = 0;
  std::array<std::array<double, 4>, 3> qform{}; // RAS, rows
  std::array<std::array<double, 4>, 3> sform{};
  std::array<double, 3> pixdim{};
};

template <class T>
T readField(const unsigned char* header, std::size_t offset, bool swap)
{
  T value;
  unsigned char bytes[sizeof(T)];
  std::memcpy(bytes, header + offset, sizeof(T));
  if (swap) std::reverse(bytes, bytes + sizeof(T));
  std::memcpy(&value, bytes, sizeof(T));
  return value;
}

bool readNiftiTransforms(const fs::path& path, NiftiTransforms& out)
{
  gzFile file = gzopen(path.c_str(), "rb");
  if (!file) return false;
  unsigned char header[348];
  const int got = gzread(file, header, sizeof(header));
  gzclose(file);
  if (got != static_cast<int>(sizeof(header))) return false;
  bool swap = false;
  if (readField<int>(header, 0, false) != 348) {
    if (readField<int>(header, 0, true) != 348) return false; // NIfTI-2 or not NIfTI: not checked
    swap = true;
  }
  auto f = [&](std::size_t offset) { return static_cast<double>(readField<float>(header, offset, swap)); };
  out.qformCode = readField<short>(header, 252, swap);
  out.sformCode = readField<short>(header, 254, swap);
  const double b = f(256), c = f(260), d = f(264);
  const double a = std::sqrt(std::max(0.0, 1.0 - (b * b + c * c + d * d)));
  double qfac = f(76);
  qfac = qfac < 0 ? -1.0 : 1.0;
  const double dx = f(80), dy = f(84), dz = f(88) * qfac;
  const double R[3][3] = {{a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)},
                          {2 * (b * c + a * d), a * a + c * c - b * b - d * d, 2 * (c * d - a * b)},
                          {2 * (b * d - a * c), 2 * (c * d + a * b), a * a + d * d - c * c - b * b}};
  const double spacing[3] = {dx, dy, dz};
  out.pixdim = {f(80), f(84), f(88)};
  const double offset[3] = {f(268), f(272), f(276)};
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) out.qform[r][col] = R[r][col] * spacing[col];
    out.qform[r][3] = offset[r];
    for (int col = 0; col < 4; ++col) out.sform[r][col] = f(280 + 16 * r + 4 * col);
  }
  return true;
}

/// InputError for a NIfTI header whose geometry holds NaN or infinite numbers (pixdim, and the
/// qform or sform in use): ITK's reader aborts the process on them (vnl's SVD asserts finite input).
void requireFiniteNiftiGeometry(const fs::path& path)
{
  NiftiTransforms t;
  if (!readNiftiTransforms(path, t)) return; // not NIfTI-1: ITK's reader decides
  auto finite = [](const std::array<std::array<double, 4>, 3>& m) {
    for (const auto& row : m) {
      for (double v : row) {
        if (!std::isfinite(v)) return false;
      }
    }
    return true;
  };
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(t.pixdim[i])) {
      throw InputError(path.string() + ": the NIfTI header's voxel size (pixdim) along axis " + std::to_string(i) +
                       " is not a finite number");
    }
  }
  if (t.qformCode > 0 && !finite(t.qform)) throw InputError(path.string() + ": the NIfTI header's qform holds NaN or infinite numbers");
  if (t.sformCode > 0 && !finite(t.sform)) throw InputError(path.string() + ": the NIfTI header's sform holds NaN or infinite numbers");
}

void checkNiftiOrientation(const fs::path& path, const ScalarImage::PointType& itkOrigin, Warnings* warnings)
{
  NiftiTransforms t;
  if (!readNiftiTransforms(path, t) || t.qformCode <= 0 || t.sformCode <= 0) return;
  double axisDifference = 0, originDifference = 0;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) axisDifference = std::max(axisDifference, std::abs(t.qform[r][c] - t.sform[r][c]));
    originDifference += (t.qform[r][3] - t.sform[r][3]) * (t.qform[r][3] - t.sform[r][3]);
  }
  originDifference = std::sqrt(originDifference);
  if (axisDifference < 1e-3 && originDifference < 1e-2) return;
  // Which one ITK used: compare its LPS origin with each (RAS -> LPS flips x and y).
  auto distanceToItk = [&](const std::array<std::array<double, 4>, 3>& m) {
    const double lps[3] = {-m[0][3], -m[1][3], m[2][3]};
    double s = 0;
    for (int i = 0; i < 3; ++i) s += (lps[i] - itkOrigin[i]) * (lps[i] - itkOrigin[i]);
    return std::sqrt(s);
  };
  const char* used = distanceToItk(t.sform) <= distanceToItk(t.qform) ? "sform" : "qform";
  std::ostringstream message;
  message << path.string() << ": NIfTI qform and sform disagree (origins " << originDifference
          << " mm apart, axis entries differ by up to " << axisDifference << "); the " << used
          << " was used";
  warn(warnings, message.str());
}

/// ITK's NIfTI reader (nifticlib) hides two kinds of damage: it zero-fills the voxels of a
/// truncated file, and it silently replaces NaN and infinite floats by 0. Both are errors in an
/// input, so the voxel data are checked here, from the file itself, in one decompression pass.
void checkNiftiVoxelData(const fs::path& path)
{
  gzFile file = gzopen(path.c_str(), "rb");
  if (!file) throw InputError(path.string() + ": cannot be opened for reading");
  unsigned char header[348];
  std::uint64_t available = static_cast<std::uint64_t>(std::max(0, gzread(file, header, sizeof(header))));
  const bool nifti1 = available == sizeof(header) &&
                      (readField<int>(header, 0, false) == 348 || readField<int>(header, 0, true) == 348);
  if (!nifti1) { // NIfTI-2 is not checked here
    gzclose(file);
    return;
  }
  const bool swap = readField<int>(header, 0, false) != 348;
  const short dimensions = readField<short>(header, 40, swap);
  const short datatype = readField<short>(header, 70, swap);
  const std::size_t floatBytes = datatype == 16 ? 4 : datatype == 64 ? 8 : 0; // float32, float64
  const std::uint64_t offset = static_cast<std::uint64_t>(std::max(0.0f, readField<float>(header, 108, swap)));
  std::uint64_t voxelBytes = static_cast<std::uint64_t>(std::max<short>(0, readField<short>(header, 72, swap))) / 8;
  for (short i = 1; i <= std::min<short>(dimensions, 7); ++i) {
    voxelBytes *= static_cast<std::uint64_t>(std::max<short>(1, readField<short>(header, 40 + 2 * i, swap)));
  }
  const std::uint64_t needed = std::max<std::uint64_t>(offset, available) + voxelBytes;
  std::vector<unsigned char> buffer(1 << 20);
  std::size_t nonFinite = 0;
  while (available < needed) {
    const std::uint64_t want = std::min<std::uint64_t>(buffer.size(), needed - available);
    const int got = gzread(file, buffer.data(), static_cast<unsigned>(want));
    if (got <= 0) break;
    // Voxels start at `offset`; buffers are whole multiples of the float size past it.
    if (floatBytes && available + std::uint64_t(got) > offset) {
      const std::size_t first = available >= offset ? 0 : std::size_t(offset - available);
      for (std::size_t i = first; i + floatBytes <= std::size_t(got); i += floatBytes) {
        const double v = floatBytes == 4 ? double(readField<float>(buffer.data(), i, swap))
                                         : readField<double>(buffer.data(), i, swap);
        if (!std::isfinite(v)) ++nonFinite;
      }
    }
    available += static_cast<std::uint64_t>(got);
  }
  gzclose(file);
  if (available < needed) {
    throw InputError(path.string() + ": truncated NIfTI file: the header announces " + std::to_string(needed) +
                     " bytes, the file holds " + std::to_string(available));
  }
  if (nonFinite > 0) {
    throw InputError(path.string() + ": " + std::to_string(nonFinite) + " voxels are NaN or infinite");
  }
}

// ---- DICOM ------------------------------------------------------------------------------
void checkSliceSpacing(const fs::path& folder, const std::vector<std::string>& files)
{
  if (files.size() < 2) {
    throw InputError(folder.string() + ": a DICOM series of " + std::to_string(files.size()) +
                     " slice; at least 2 are needed for a volume");
  }
  std::vector<double> positions;
  itk::Vector<double, 3> normal;
  normal.Fill(0.0);
  std::array<double, 6> firstOrientation{};
  for (std::size_t i = 0; i < files.size(); ++i) {
    auto io = itk::GDCMImageIO::New();
    io->SetFileName(files[i]);
    try {
      io->ReadImageInformation();
    } catch (const itk::ExceptionObject& e) {
      throw InputError(files[i] + ": cannot read the DICOM header: " + oneLine(e.GetDescription()));
    }
    const std::vector<double> row = io->GetDirection(0), column = io->GetDirection(1);
    std::array<double, 6> orientation{row[0], row[1], row[2], column[0], column[1], column[2]};
    if (i == 0) {
      firstOrientation = orientation;
      normal[0] = row[1] * column[2] - row[2] * column[1];
      normal[1] = row[2] * column[0] - row[0] * column[2];
      normal[2] = row[0] * column[1] - row[1] * column[0];
    } else {
      for (int k = 0; k < 6; ++k) {
        if (std::abs(orientation[k] - firstOrientation[k]) > 1e-3) {
          throw InputError(folder.string() + ": slice " + files[i] +
                           " has another orientation than the first slice; mixed orientations are not one volume");
        }
      }
    }
    positions.push_back(io->GetOrigin(0) * normal[0] + io->GetOrigin(1) * normal[1] + io->GetOrigin(2) * normal[2]);
  }
  std::sort(positions.begin(), positions.end());
  std::vector<double> gaps;
  for (std::size_t i = 1; i < positions.size(); ++i) gaps.push_back(positions[i] - positions[i - 1]);
  std::vector<double> sorted = gaps;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  const double typical = sorted[sorted.size() / 2];
  if (!(typical > 1e-6)) {
    throw InputError(folder.string() + ": several slices share one position; not a single volume");
  }
  for (std::size_t i = 0; i < gaps.size(); ++i) {
    if (std::abs(gaps[i] - typical) > 0.01 * typical + 1e-3) {
      std::ostringstream message;
      message << folder.string() << ": irregular DICOM series: slices " << i << " and " << i + 1
              << " are " << gaps[i] << " mm apart where the series' spacing is " << typical
              << " mm (missing or uneven slices); refused";
      throw InputError(message.str());
    }
  }
}

constexpr std::uint64_t NiftiSingleFileHeaderBytes = 352;

template <class TOutputPixel, class TInputImage>
void writeAs(const TInputImage* image, const fs::path& path, bool compress = true)
{
  using OutputImage = itk::Image<TOutputPixel, 3>;
  auto writer = itk::ImageFileWriter<OutputImage>::New();
  typename OutputImage::Pointer converted;
  if constexpr (std::is_same_v<OutputImage, TInputImage>) {
    converted = const_cast<TInputImage*>(image);
  } else {
    converted = OutputImage::New();
    converted->CopyInformation(image);
    converted->SetRegions(image->GetLargestPossibleRegion());
    converted->Allocate();
    const auto* in = image->GetBufferPointer();
    auto* out = converted->GetBufferPointer();
    const std::size_t n = image->GetLargestPossibleRegion().GetNumberOfPixels();
    constexpr double lo = static_cast<double>(std::numeric_limits<TOutputPixel>::lowest());
    constexpr double hi = static_cast<double>(std::numeric_limits<TOutputPixel>::max());
    for (std::size_t i = 0; i < n; ++i) {
      const double v = std::round(static_cast<double>(in[i]));
      out[i] = static_cast<TOutputPixel>(std::clamp(v, lo, hi));
    }
  }
  writer->SetInput(converted);
  // A compressed single-file NIfTI-1 as ITK writes it: the 348-byte header, the 4-byte extension
  // flag (no extensions), then the voxels; were it otherwise, every such write would be refused as
  // incomplete (every test that writes a volume would fail).
  if (compress && hasExtension(path, {".nii.gz"})) {
    const std::uint64_t contentBytes =
      NiftiSingleFileHeaderBytes + std::uint64_t(image->GetLargestPossibleRegion().GetNumberOfPixels()) * sizeof(TOutputPixel);
    writeAtomicallyGzipped(writer.GetPointer(), path, contentBytes);
    return;
  }
  writeAtomically(writer.GetPointer(), path, compress);
}

} // namespace

bool isVolumePath(const fs::path& path)
{
  std::error_code ec;
  if (fs::is_directory(path, ec)) return true;
  return hasExtension(path, {".nii", ".nii.gz", ".nrrd", ".nhdr", ".mha", ".mhd"});
}

ScalarImage::Pointer readDicomSeries(const fs::path& folder, Warnings* warnings)
{
  registerIOFactories();
  auto names = itk::GDCMSeriesFileNames::New();
  names->SetUseSeriesDetails(true);
  names->SetDirectory(folder.string());
  const std::vector<std::string> series = names->GetSeriesUIDs();
  if (series.empty()) {
    throw InputError(folder.string() + ": the folder holds no DICOM series");
  }
  if (series.size() > 1) {
    throw InputError(folder.string() + ": the folder holds " + std::to_string(series.size()) +
                     " DICOM series; give the folder of one series");
  }
  const std::vector<std::string> files = names->GetFileNames(series.front());
  checkSliceSpacing(folder, files);
  using SeriesReader = itk::ImageSeriesReader<ScalarImage>;
  auto reader = SeriesReader::New();
  auto io = itk::GDCMImageIO::New();
  reader->SetImageIO(io);
  reader->SetFileNames(files);
  try {
    reader->Update();
  } catch (const itk::ExceptionObject& e) {
    throw InputError(folder.string() + ": cannot read the DICOM series: " + oneLine(e.GetDescription()));
  }
  ScalarImage::Pointer image = reader->GetOutput();
  image->DisconnectPipeline();
  requireFinite(image, folder);
  (void)warnings;
  return image;
}

ScalarImage::Pointer readScalarVolume(const fs::path& path, Warnings* warnings)
{
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    return readDicomSeries(path, warnings);
  }
  if (isNiftiFile(path)) requireFiniteNiftiGeometry(path);
  readImageHeader(path, 1);
  if (isNiftiFile(path)) checkNiftiVoxelData(path);
  ScalarImage::Pointer image = readImageFile<ScalarImage>(path);
  requireFinite(image, path);
  if (isNiftiFile(path)) {
    checkNiftiOrientation(path, image->GetOrigin(), warnings);
  }
  return image;
}

LabelImage::Pointer readLabelVolume(const fs::path& path, Warnings* warnings)
{
  ScalarImage::Pointer values = readScalarVolume(path, warnings);
  auto labels = LabelImage::New();
  labels->CopyInformation(values);
  labels->SetRegions(values->GetLargestPossibleRegion());
  labels->Allocate();
  const float* in = values->GetBufferPointer();
  LabelPixel* out = labels->GetBufferPointer();
  const std::size_t n = values->GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) {
    const float v = in[i];
    if (v < 0 || v > 65535 || v != std::floor(v)) {
      std::ostringstream message;
      message << path.string() << ": not a label map: voxel value " << v
              << " (labels are integers from 0 to 65535)";
      throw InputError(message.str());
    }
    out[i] = static_cast<LabelPixel>(v);
  }
  return labels;
}

DisplacementFieldImage::Pointer readDisplacementField(const fs::path& path)
{
  if (isNiftiFile(path)) requireFiniteNiftiGeometry(path);
  readImageHeader(path, 3);
  if (isNiftiFile(path)) checkNiftiVoxelData(path);
  DisplacementFieldImage::Pointer field = readImageFile<DisplacementFieldImage>(path);
  const std::size_t n = field->GetLargestPossibleRegion().GetNumberOfPixels();
  const DisplacementVector* d = field->GetBufferPointer();
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(d[i][0]) || !std::isfinite(d[i][1]) || !std::isfinite(d[i][2])) {
      throw InputError(path.string() + ": the displacement field has NaN or infinite vectors");
    }
  }
  return field;
}

void writeScalarVolume(const ScalarImage* image, const fs::path& path, StoredPixelType stored)
{
  registerIOFactories();
  switch (stored) {
  case StoredPixelType::Float32: writeAs<float>(image, path); break;
  case StoredPixelType::Int16: writeAs<short>(image, path); break;
  case StoredPixelType::UInt8: writeAs<unsigned char>(image, path); break;
  }
}

void writeLabelVolume(const LabelImage* image, const fs::path& path)
{
  registerIOFactories();
  LabelPixel maximum = 0;
  const std::size_t n = image->GetLargestPossibleRegion().GetNumberOfPixels();
  for (std::size_t i = 0; i < n; ++i) maximum = std::max(maximum, image->GetBufferPointer()[i]);
  // uint8 on disk when the labels fit: a quarter of the size, and what most tools expect.
  if (maximum <= 255) {
    writeAs<unsigned char>(image, path);
  } else {
    writeAs<LabelPixel>(image, path);
  }
}

void writeDisplacementField(const DisplacementFieldImage* field, const fs::path& path)
{
  registerIOFactories();
  // Only a .gz name asks for compression; a field's floats hardly compress.
  const std::string name = lowerCaseFileName(path);
  const bool gzipped = name.size() > 3 && name.compare(name.size() - 3, 3, ".gz") == 0;
  writeAs<DisplacementVector>(field, path, gzipped);
}

} // namespace brainshift
