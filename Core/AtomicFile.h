#pragma once
// Outputs are written atomically: to a temporary name in the target's folder, then renamed.
// A reader never sees a half-written file, and a failure leaves no partial output behind.
#include <filesystem>
#include <string>

namespace brainshift {

class AtomicFile {
public:
  /// Creates the target's folder if needed. The temporary name keeps the target's extension
  /// (".tmp-<pid>-<n>-name.nii.gz"), so writers that choose a format by extension still work.
  explicit AtomicFile(std::filesystem::path target);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  const std::filesystem::path& temporaryPath() const { return temporary_; }
  const std::filesystem::path& targetPath() const { return target_; }

  /// Renames the temporary file onto the target. Throws std::runtime_error if it is missing.
  void commit();

private:
  std::filesystem::path target_;
  std::filesystem::path temporary_;
  bool committed_ = false;
};

/// Writes `text` to `target` atomically.
void writeTextFileAtomically(const std::filesystem::path& target, const std::string& text);

/// Reads a whole text file; InputError naming the file if it cannot.
std::string readTextFile(const std::filesystem::path& path);

} // namespace brainshift
