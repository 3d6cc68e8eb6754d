#include "OutputFolder.h"

#include "BrainShiftErrors.h"
#include "ProcessCleanup.h"

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <map>
#include <mutex>
#include <string>
#include <sys/file.h>
#include <unistd.h>

namespace brainshift {
namespace fs = std::filesystem;

namespace {
/// The same folder however it is named (relative, with "..", through a link).
fs::path canonicalName(const fs::path& path)
{
  std::error_code ec;
  fs::path name = fs::weakly_canonical(fs::absolute(path), ec);
  return ec ? fs::absolute(path).lexically_normal() : name;
}

/// Folders this process created: when a run refuses its input they are empty, and
/// go at exit (a refused run leaves nothing behind).
std::vector<fs::path>& createdFolders()
{
  static std::vector<fs::path>* folders = new std::vector<fs::path>;
  return *folders;
}

void removeUnusedCreatedFolders()
{
  for (const fs::path& folder : createdFolders()) {
    std::error_code ec;
    auto entries = fs::directory_iterator(folder, ec);
    if (ec) continue;
    if (entries == fs::directory_iterator()) fs::remove(folder, ec);
  }
}

void requireWritable(const fs::path& folder)
{
  std::error_code ec;
  if (!fs::exists(folder, ec)) {
    if (createdFolders().empty()) std::atexit(removeUnusedCreatedFolders);
    createdFolders().push_back(fs::absolute(folder));
  }
  fs::create_directories(folder, ec);
  if (ec) throw InputError(folder.string() + ": cannot create the output folder (" + ec.message() + ")");
  if (!fs::is_directory(folder, ec)) throw InputError(folder.string() + ": --output-dir is not a folder");
  if (::access(folder.c_str(), W_OK | X_OK) != 0) {
    throw InputError(folder.string() + ": the output folder is not writable (" + std::strerror(errno) + ")");
  }
}
} // namespace

void claimOutputFolder(const fs::path& folder)
{
  static std::mutex mutex;
  static std::map<fs::path, int> held; // folder -> the descriptor holding its lock, for the process's life
  std::lock_guard<std::mutex> guard(mutex);
  requireWritable(folder);
  const fs::path name = canonicalName(folder);
  if (held.count(name)) return;
  // The lock is on the folder itself: nothing is added to it, and it goes with the process.
  const int fd = ::open(name.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) throw InputError(folder.string() + ": cannot open the output folder (" + std::strerror(errno) + ")");
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    ::close(fd);
    throw InputError(folder.string() + ": another brainshift run is writing into this folder; wait for it to end or "
                     "choose another --output-dir");
  }
  held[name] = fd;
  cleanup::removeStaleTemporaries(name);
}

void refuseOutputOverInputs(const fs::path& output, const std::vector<fs::path>& inputs, const char* outputFlag)
{
  const fs::path out = canonicalName(output);
  for (const fs::path& input : inputs) {
    if (input.empty()) continue;
    const fs::path in = canonicalName(input);
    if (in == out) {
      throw InputError(output.string() + ": " + outputFlag + " is an input (" + input.string() +
                       "); inputs are never overwritten, choose another path");
    }
  }
}

void refuseInputsAmongOutputs(const fs::path& outputFolder, const std::vector<fs::path>& inputs)
{
  static const char* const written[] = {"rigid_intraop_to_preop.tfm", "intraop_to_preop.h5", "displacement_intraop_to_preop.nrrd",
                                        "intraop_labels.nii.gz", "mesh.vtu", "brain_surface.vtp",
                                        "displacement_uncertainty_mm.nii.gz", "scene.mrml", "report.json"};
  const fs::path out = canonicalName(outputFolder);
  for (const fs::path& input : inputs) {
    if (input.empty()) continue;
    const fs::path in = canonicalName(input);
    if (in.parent_path() != out) continue;
    const std::string name = in.filename().string();
    bool collides = name.rfind("warped_", 0) == 0;
    for (const char* file : written) collides = collides || name == file;
    if (collides) {
      throw InputError(input.string() + ": this input is in --output-dir under a name the run writes (" + name +
                       "); it would be overwritten: move it or choose another --output-dir");
    }
  }
}

} // namespace brainshift
