#pragma once
// Runs an ITK writer (image or transform) onto a path atomically, compressed where the format
// allows. Internal to MRML's writers.
#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "LibraryMessages.h"

#include <itkMacro.h>

#include <stdexcept>

namespace brainshift {

/// `compress` off for data zlib cannot shrink much (dense displacement fields of floats: a few
/// percent smaller for seconds of compression on a 4-million-voxel field). `gzipContentBytes`: the
/// written stream's length before compression, when the caller knows it (AtomicFile::commit).
template <class TWriter>
void writeAtomically(TWriter* writer, const std::filesystem::path& path, bool compress = true,
                     std::optional<std::uint64_t> gzipContentBytes = std::nullopt)
{
  AtomicFile file(path);
  writer->SetFileName(file.temporaryPath().string());
  writer->SetUseCompression(compress);
  try {
    // NIfTI's library prints "** ERROR: NWAD: wrote only ..." itself and carries on; the file is
    // verified below and the error reported once, naming it.
    const MutedStderr muted;
    writer->Update();
  } catch (const itk::ExceptionObject& e) {
    throw MethodError("cannot write " + path.string() + ": " + oneLine(e.GetDescription()));
  }
  file.commit(gzipContentBytes); // verifies the file first: NIfTI's writer does not notice a full disk
}

} // namespace brainshift
