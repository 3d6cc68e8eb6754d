#include "LibraryDiagnostics.h"

#include <itkObject.h>
#include <vtkObject.h>

#include <cstdint>
#include <dlfcn.h>

namespace brainshift::cli {

void silenceLibraryDiagnostics()
{
  vtkObject::GlobalWarningDisplayOff();
  itk::Object::GlobalWarningDisplayOff();
  // HDF5 and GDCM come in through ITK's transform and DICOM readers; their symbols are looked up
  // where ITK loaded them, so that the same library instance is told (the CLI does not link them).
  using H5EsetAuto = int (*)(std::int64_t, void*, void*);
  if (auto setAuto = reinterpret_cast<H5EsetAuto>(::dlsym(RTLD_DEFAULT, "H5Eset_auto2"))) {
    setAuto(0 /* H5E_DEFAULT */, nullptr, nullptr);
  }
  for (const char* off : {"_ZN4gdcm5Trace10WarningOffEv", "_ZN4gdcm5Trace8DebugOffEv", "_ZN4gdcm5Trace8ErrorOffEv"}) {
    if (auto turnOff = reinterpret_cast<void (*)()>(::dlsym(RTLD_DEFAULT, off))) turnOff();
  }
}

} // namespace brainshift::cli
