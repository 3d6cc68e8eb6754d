#pragma once
// Runs an ITK writer (image or transform) onto a path atomically, compressed where the format
// allows. Internal to MRML's writers.
#include "AtomicFile.h"

#include <itkMacro.h>

#include <stdexcept>

namespace brainshift {

template <class TWriter>
void writeAtomically(TWriter* writer, const std::filesystem::path& path)
{
  AtomicFile file(path);
  writer->SetFileName(file.temporaryPath().string());
  writer->SetUseCompression(true);
  try {
    writer->Update();
  } catch (const itk::ExceptionObject& e) {
    throw std::runtime_error("cannot write " + path.string() + ": " + e.GetDescription());
  }
  file.commit();
}

} // namespace brainshift
