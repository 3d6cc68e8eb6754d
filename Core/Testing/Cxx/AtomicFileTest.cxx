// Outputs are written atomically: a reader sees the old file or the whole new one, never a part;
// a write that fails or is abandoned leaves the target as it was and no temporary behind.
#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"

#include <zlib.h>

#include <fstream>
#include <string>
#include <unistd.h>

namespace {
namespace fs = std::filesystem;

/// The names in `folder` that start with ".tmp-": what a write left behind.
std::size_t temporariesIn(const fs::path& folder)
{
  std::size_t count = 0;
  for (const auto& entry : fs::directory_iterator(folder)) {
    if (entry.path().filename().string().rfind(".tmp-", 0) == 0) ++count;
  }
  return count;
}

void writeGzip(const fs::path& path, const std::string& text)
{
  gzFile out = ::gzopen(path.c_str(), "wb");
  BS_CHECK(out != nullptr);
  BS_CHECK(::gzwrite(out, text.data(), unsigned(text.size())) == int(text.size()));
  BS_CHECK(::gzclose(out) == Z_OK);
}
} // namespace

int AtomicFileTest(int, char*[])
{
  return brainshift::testing::runTest("AtomicFileTest", [] {
    using namespace brainshift;
    const fs::path folder = testing::temporaryFolder("AtomicFileTest");

    // A new file in a folder that does not exist yet; then replaced whole.
    const fs::path text = folder / "nested" / "deeper" / "report.json";
    writeTextFileAtomically(text, "{\"first\": 1}");
    BS_CHECK(readTextFile(text) == "{\"first\": 1}");
    writeTextFileAtomically(text, "{}");
    BS_CHECK(readTextFile(text) == "{}");
    BS_CHECK(temporariesIn(text.parent_path()) == 0);
    writeTextFileAtomically(folder / "empty.txt", "");
    BS_CHECK(fs::exists(folder / "empty.txt") && fs::file_size(folder / "empty.txt") == 0);

    // The temporary sits beside the target, names this process and keeps the target's extension
    // (writers that pick the format by extension still work).
    const fs::path image = folder / "warped.nii.gz";
    {
      AtomicFile file(image);
      const std::string name = file.temporaryPath().filename().string();
      BS_CHECK_MSG(name.rfind(".tmp-" + std::to_string(::getpid()) + "-", 0) == 0, name);
      BS_CHECK_MSG(name.size() > 13 && name.compare(name.size() - 13, 13, "warped.nii.gz") == 0, name);
      BS_CHECK(file.temporaryPath().parent_path() == folder);
      writeGzip(file.temporaryPath(), "the whole volume");
      file.commit();
    }
    BS_CHECK(fs::exists(image) && temporariesIn(folder) == 0);
    const auto committedSize = fs::file_size(image);

    // Abandoned (an exception between write and commit): the old target stays, the temporary goes.
    {
      AtomicFile file(image);
      writeGzip(file.temporaryPath(), "a newer volume that is never committed");
      BS_CHECK(temporariesIn(folder) == 1);
    }
    BS_CHECK(fs::file_size(image) == committedSize && temporariesIn(folder) == 0);

    // Nothing written (a writer that failed silently): refused, naming the target.
    {
      AtomicFile file(image);
      BS_CHECK_THROWS(file.commit(), MethodError, "nothing was written");
    }
    {
      AtomicFile file(image);
      std::ofstream(file.temporaryPath()).close(); // created, empty
      BS_CHECK_THROWS(file.commit(), MethodError, image.string());
    }
    // A gzip stream cut short (disk full mid-write): the writer did not notice, the commit does.
    {
      AtomicFile file(image);
      writeGzip(file.temporaryPath(), std::string(1 << 16, 'x') + "the end");
      fs::resize_file(file.temporaryPath(), fs::file_size(file.temporaryPath()) - 6);
      BS_CHECK_THROWS(file.commit(), MethodError, "incomplete");
    }
    BS_CHECK(fs::file_size(image) == committedSize && temporariesIn(folder) == 0);
    // The same, checked from the stream's trailer when the writer knows the content's length (the
    // volume writers do): the whole stream passes, a stream cut short or of another length does not.
    const std::string content = std::string(1 << 16, 'y') + "the end";
    {
      AtomicFile file(image);
      writeGzip(file.temporaryPath(), content);
      file.commit(content.size());
    }
    BS_CHECK(temporariesIn(folder) == 0);
    const auto trailerCheckedSize = fs::file_size(image);
    {
      AtomicFile file(image);
      writeGzip(file.temporaryPath(), content);
      fs::resize_file(file.temporaryPath(), fs::file_size(file.temporaryPath()) - 6);
      BS_CHECK_THROWS(file.commit(content.size()), MethodError, "incomplete");
    }
    {
      AtomicFile file(image);
      writeGzip(file.temporaryPath(), content);
      BS_CHECK_THROWS(file.commit(content.size() + 1), MethodError, "incomplete");
    }
    BS_CHECK(fs::file_size(image) == trailerCheckedSize && temporariesIn(folder) == 0);

    // A folder that cannot be made: a plain file stands where the folder should be.
    std::ofstream(folder / "blocker").close();
    BS_CHECK_THROWS(writeTextFileAtomically(folder / "blocker" / "x.json", "{}"), InputError, "cannot create folder");

    // Reading: one error naming the file.
    BS_CHECK_THROWS(readTextFile(folder / "missing.json"), InputError, "missing.json: no such file");
    BS_CHECK_THROWS(readTextFile(folder / "nested"), InputError, "a folder, not a file");
  });
}
