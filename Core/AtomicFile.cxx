#include "AtomicFile.h"

#include "BrainShiftErrors.h"
#include "ProcessCleanup.h"

#include <zlib.h>

#include <atomic>
#include <fstream>
#include <sstream>
#include <sys/resource.h>
#include <system_error>
#include <unistd.h>

namespace brainshift {
namespace fs = std::filesystem;

namespace {
std::atomic<unsigned> temporaryCounter{0};

bool endsWith(const std::string& text, const std::string& tail)
{
  return text.size() >= tail.size() && text.compare(text.size() - tail.size(), tail.size(), tail) == 0;
}

/// Whether a gzip file decompresses to its end: a write cut short (full disk, file-size limit)
/// leaves a stream without its trailer, which some writers (NIfTI's) do not notice.
bool completeGzip(const fs::path& path)
{
  gzFile in = ::gzopen(path.c_str(), "rb");
  if (!in) return false;
  char buffer[1 << 16];
  int got = 0;
  while ((got = ::gzread(in, buffer, sizeof buffer)) > 0) {
  }
  int error = Z_OK;
  ::gzerror(in, &error);
  const bool complete = got == 0 && error == Z_OK;
  return ::gzclose(in) == Z_OK && complete;
}

/// Whether a gzip file ends as a whole stream of `contentBytes` bytes does: it starts with gzip's
/// magic and its last 4 bytes (the trailer's ISIZE, the content's length modulo 2^32, little-endian)
/// hold that length. A stream cut short ends in compressed data instead, which matches with a
/// chance of 2^-32.
bool gzipEndsAfter(const fs::path& path, std::uint64_t contentBytes)
{
  std::ifstream in(path, std::ios::binary);
  unsigned char magic[2] = {0, 0}, trailer[4] = {0, 0, 0, 0};
  if (!in.read(reinterpret_cast<char*>(magic), 2) || magic[0] != 0x1f || magic[1] != 0x8b) return false;
  if (!in.seekg(-4, std::ios::end) || !in.read(reinterpret_cast<char*>(trailer), 4)) return false;
  const std::uint32_t length = std::uint32_t(trailer[0]) | std::uint32_t(trailer[1]) << 8 | std::uint32_t(trailer[2]) << 16 |
                               std::uint32_t(trailer[3]) << 24;
  return length == std::uint32_t(contentBytes & 0xffffffffu);
}

/// MethodError naming `target` unless `written` holds a whole file.
void verifyWrittenFile(const fs::path& written, const fs::path& target, std::optional<std::uint64_t> gzipContentBytes)
{
  std::error_code ec;
  const auto size = fs::is_regular_file(written, ec) ? fs::file_size(written, ec) : 0;
  if (ec || size == 0) throw MethodError("cannot write " + target.string() + ": nothing was written (disk full or not writable?)");
  rlimit limit{};
  if (::getrlimit(RLIMIT_FSIZE, &limit) == 0 && limit.rlim_cur != RLIM_INFINITY && size >= limit.rlim_cur) {
    throw MethodError("cannot write " + target.string() + ": the file reached the file-size limit (" +
                      std::to_string(limit.rlim_cur) + " bytes) and is incomplete");
  }
  if (endsWith(target.string(), ".gz") && !(gzipContentBytes ? gzipEndsAfter(written, *gzipContentBytes) : completeGzip(written))) {
    throw MethodError("cannot write " + target.string() + ": the written file is incomplete (disk full?)");
  }
}
} // namespace

AtomicFile::AtomicFile(fs::path target)
  : target_(std::move(target))
{
  const fs::path folder = target_.has_parent_path() ? target_.parent_path() : fs::path(".");
  temporary_ = folder / (".tmp-" + std::to_string(::getpid()) + "-" +
                         std::to_string(temporaryCounter++) + "-" + target_.filename().string());
  // Registered before its folder is made: a run ending on a signal removes its folders, and a
  // writer must not make one again behind the cleanup (it blocks here instead).
  std::error_code ec;
  cleanup::createRegistered(temporary_, [&] { fs::create_directories(folder, ec); });
  if (ec) {
    cleanup::withdrawTemporaryPath(temporary_);
    throw InputError("cannot create folder " + folder.string() + ": " + ec.message());
  }
}

AtomicFile::~AtomicFile()
{
  if (!committed_) {
    std::error_code ignored;
    fs::remove(temporary_, ignored);
  }
  cleanup::withdrawTemporaryPath(temporary_);
}

void AtomicFile::commit(std::optional<std::uint64_t> gzipContentBytes)
{
  verifyWrittenFile(temporary_, target_, gzipContentBytes);
  std::error_code ec;
  fs::rename(temporary_, target_, ec);
  if (ec) {
    throw MethodError("cannot move " + temporary_.string() + " onto " + target_.string() + ": " + ec.message());
  }
  committed_ = true;
  cleanup::withdrawTemporaryPath(temporary_);
}

void writeTextFileAtomically(const fs::path& target, const std::string& text)
{
  AtomicFile file(target);
  {
    std::ofstream out(file.temporaryPath(), std::ios::binary);
    out << text;
    out.flush();
    out.close();
    std::error_code ec;
    if (!out || fs::file_size(file.temporaryPath(), ec) != text.size() || ec) {
      throw MethodError("cannot write " + target.string() + " (disk full or not writable?)");
    }
  }
  if (text.empty()) { // nothing to verify beyond the size
    std::error_code ec;
    fs::rename(file.temporaryPath(), target, ec);
    if (ec) throw MethodError("cannot move " + file.temporaryPath().string() + " onto " + target.string() + ": " + ec.message());
    return;
  }
  file.commit();
}

std::string readTextFile(const fs::path& path)
{
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    throw InputError(path.string() + ": no such file");
  }
  if (fs::is_directory(path, ec)) {
    throw InputError(path.string() + ": a folder, not a file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw InputError(path.string() + ": cannot be opened for reading");
  }
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

} // namespace brainshift
