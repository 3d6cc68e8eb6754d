#include "GzipCompression.h"

#include "BrainShiftErrors.h"

#include <libdeflate.h>

#include <fstream>
#include <memory>
#include <string>
#include <vector>

namespace brainshift {
namespace fs = std::filesystem;

void gzipFile(const fs::path& source, const fs::path& destination, std::uint64_t expectedBytes, const fs::path& target, int level)
{
  std::error_code ec;
  const std::uint64_t size = fs::file_size(source, ec);
  if (ec || size != expectedBytes) {
    throw MethodError("cannot write " + target.string() + ": " + std::to_string(ec ? 0 : size) + " of " + std::to_string(expectedBytes) +
                      " bytes were written before compression (disk full or not writable?)");
  }
  std::vector<char> content(size);
  {
    std::ifstream in(source, std::ios::binary);
    if (!in.read(content.data(), std::streamsize(size))) {
      throw MethodError("cannot write " + target.string() + ": cannot read back " + source.string() + " to compress it");
    }
  }
  const std::unique_ptr<libdeflate_compressor, decltype(&libdeflate_free_compressor)> compressor(libdeflate_alloc_compressor(level),
                                                                                                 &libdeflate_free_compressor);
  if (!compressor) throw MethodError("cannot write " + target.string() + ": no memory for the compressor (level " + std::to_string(level) + ")");
  std::vector<char> compressed(libdeflate_gzip_compress_bound(compressor.get(), content.size()));
  const std::size_t compressedBytes =
    libdeflate_gzip_compress(compressor.get(), content.data(), content.size(), compressed.data(), compressed.size());
  if (compressedBytes == 0) throw MethodError("cannot write " + target.string() + ": compression failed");
  std::ofstream out(destination, std::ios::binary | std::ios::trunc);
  out.write(compressed.data(), std::streamsize(compressedBytes));
  out.close();
  if (!out) throw MethodError("cannot write " + target.string() + ": " + destination.string() + " could not be written (disk full?)");
}

} // namespace brainshift
