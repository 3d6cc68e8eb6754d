#pragma once
// Outputs are written atomically: to a temporary name in the target's folder, then renamed.
// A reader never sees a half-written file, and a failure leaves no partial output behind.
#include <cstdint>
#include <filesystem>
#include <optional>
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

  /// Renames the temporary file onto the target, once it is verified: MethodError naming the
  /// target if it is missing, empty, at the file-size limit, or (a ".gz" target) a gzip stream
  /// without its end. `gzipContentBytes`: how long the stream's content must be, when the caller
  /// knows it; the check then reads the stream's trailer (its last 4 bytes hold that length) instead
  /// of decompressing the whole file (0.05-0.1 s for a 16 MB volume).
  void commit(std::optional<std::uint64_t> gzipContentBytes = std::nullopt);

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
