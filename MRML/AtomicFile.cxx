#include "AtomicFile.h"

#include "BrainShiftErrors.h"

#include <atomic>
#include <fstream>
#include <sstream>
#include <system_error>
#include <unistd.h>

namespace brainshift {
namespace fs = std::filesystem;

namespace {
std::atomic<unsigned> temporaryCounter{0};
}

AtomicFile::AtomicFile(fs::path target)
  : target_(std::move(target))
{
  const fs::path folder = target_.has_parent_path() ? target_.parent_path() : fs::path(".");
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec) {
    throw InputError("cannot create folder " + folder.string() + ": " + ec.message());
  }
  temporary_ = folder / (".tmp-" + std::to_string(::getpid()) + "-" +
                         std::to_string(temporaryCounter++) + "-" + target_.filename().string());
}

AtomicFile::~AtomicFile()
{
  if (!committed_) {
    std::error_code ignored;
    fs::remove(temporary_, ignored);
  }
}

void AtomicFile::commit()
{
  std::error_code ec;
  fs::rename(temporary_, target_, ec);
  if (ec) {
    throw std::runtime_error("cannot move " + temporary_.string() + " onto " + target_.string() +
                             ": " + ec.message());
  }
  committed_ = true;
}

void writeTextFileAtomically(const fs::path& target, const std::string& text)
{
  AtomicFile file(target);
  {
    std::ofstream out(file.temporaryPath(), std::ios::binary);
    out << text;
    out.close();
    if (!out) {
      throw std::runtime_error("cannot write " + target.string());
    }
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
