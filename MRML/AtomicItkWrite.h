#pragma once
// Runs an ITK writer (image or transform) onto a path atomically, compressed where the format
// allows. Internal to MRML's writers.
#include "AtomicFile.h"
#include "GzipCompression.h"
#include "BrainShiftErrors.h"
#include "LibraryMessages.h"

#include <itkMacro.h>

#include <stdexcept>

namespace brainshift {

/// Runs `writer` onto `file` (compressed or not); an ITK error is a MethodError naming `path`.
template <class TWriter>
void runWriter(TWriter* writer, const std::filesystem::path& file, bool compress, const std::filesystem::path& path)
{
  writer->SetFileName(file.string());
  writer->SetUseCompression(compress);
  try {
    // NIfTI's library prints "** ERROR: NWAD: wrote only ..." itself and carries on; the file is
    // verified afterwards and the error reported once, naming it.
    const MutedStderr muted;
    writer->Update();
  } catch (const itk::ExceptionObject& e) {
    throw MethodError("cannot write " + path.string() + ": " + oneLine(e.GetDescription()));
  }
}

/// `compress` off for data zlib cannot shrink much (dense displacement fields of floats: a few
/// percent smaller for seconds of compression on a 4-million-voxel field). A ".gz" target is
/// written by writeAtomicallyGzipped instead.
template <class TWriter>
void writeAtomically(TWriter* writer, const std::filesystem::path& path, bool compress = true)
{
  AtomicFile file(path);
  runWriter(writer, file.temporaryPath(), compress, path);
  file.commit(); // verifies the file first: NIfTI's writer does not notice a full disk
}

/// A ".gz" file as `writer` writes it uncompressed (a scratch file beside the target, removed
/// whatever happens), then gzip-compressed whole (GzipCompression.h: a quarter of the time of
/// zlib, which ITK's writers use). `contentBytes`: the uncompressed file's length, which it must have.
template <class TWriter>
void writeAtomicallyGzipped(TWriter* writer, const std::filesystem::path& path, std::uint64_t contentBytes)
{
  AtomicFile file(path);
  const AtomicFile uncompressed(path.parent_path() / path.stem()); // "x.nii.gz" -> "x.nii": never committed
  runWriter(writer, uncompressed.temporaryPath(), false, path);
  gzipFile(uncompressed.temporaryPath(), file.temporaryPath(), contentBytes, path);
  file.commit(contentBytes);
}

} // namespace brainshift
