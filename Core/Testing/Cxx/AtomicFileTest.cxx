// Outputs are written atomically: a reader sees the old file or the whole new one, never a part;
// a write that fails or is abandoned leaves the target as it was and no temporary behind.
#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "GzipCompression.h"

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

    // Whole-buffer gzip (libdeflate): a stream zlib reads back byte for byte, whose trailer holds
    // its length; a source shorter or longer than expected is refused, naming the target.
    {
      std::string volume(3 * 1024 * 1024 + 17, '\0');
      for (std::size_t i = 0; i < volume.size(); ++i) volume[i] = char((i * 2654435761u >> 13) % 7 + (i / 4096) % 3);
      const fs::path raw = folder / "volume.nii", packed = folder / "volume.nii.gz";
      std::ofstream(raw, std::ios::binary).write(volume.data(), std::streamsize(volume.size()));
      {
        AtomicFile file(packed);
        gzipFile(raw, file.temporaryPath(), volume.size(), packed);
        file.commit(volume.size());
      }
      BS_CHECK(fs::file_size(packed) < volume.size() / 4);
      gzFile in = ::gzopen(packed.c_str(), "rb");
      std::string back(volume.size() + 10, '\1');
      const int got = ::gzread(in, back.data(), unsigned(back.size()));
      ::gzclose(in);
      BS_CHECK_MSG(got == int(volume.size()) && back.compare(0, volume.size(), volume) == 0, "read back " << got << " bytes");
      AtomicFile file(packed);
      BS_CHECK_THROWS(gzipFile(raw, file.temporaryPath(), volume.size() + 1, packed), MethodError,
                      packed.string() + ": " + std::to_string(volume.size()) + " of " + std::to_string(volume.size() + 1) + " bytes");
      BS_CHECK_THROWS(gzipFile(folder / "absent.nii", file.temporaryPath(), 352, packed), MethodError, "0 of 352 bytes");
    }

    // A folder that cannot be made: a plain file stands where the folder should be.
    std::ofstream(folder / "blocker").close();
    BS_CHECK_THROWS(writeTextFileAtomically(folder / "blocker" / "x.json", "{}"), InputError, "cannot create folder");

    // Reading: one error naming the file.
    BS_CHECK_THROWS(readTextFile(folder / "missing.json"), InputError, "missing.json: no such file");
    BS_CHECK_THROWS(readTextFile(folder / "nested"), InputError, "a folder, not a file");
  });
}
