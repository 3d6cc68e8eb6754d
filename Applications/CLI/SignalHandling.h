#pragma once
// A signal ends a brainshift run cleanly (../shared/CONTRACT.md): SIGINT, SIGTERM and SIGHUP
// terminate the finite element worker's process group (mpiexec and its ranks), remove the run's
// temporary files and folders (ProcessCleanup.h), print one line and exit with 128 + the signal.
// A file-size limit (SIGXFSZ) turns into a failed write, reported as such, instead of a kill.
namespace brainshift::cli {

/// Call first in main, before any thread starts.
void installSignalHandling();

} // namespace brainshift::cli
