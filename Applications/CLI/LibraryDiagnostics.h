#pragma once
// Exactly one line on stderr per error: the libraries' own diagnostics (VTK's and ITK's output
// windows, HDF5's error stack, GDCM's traces: 4 to 21 lines for one bad file) are turned off in
// the command line; every reader and writer checks its library's status and throws one error
// naming the file and the problem instead (InputError, MethodError).
namespace brainshift::cli {

void silenceLibraryDiagnostics();

} // namespace brainshift::cli
