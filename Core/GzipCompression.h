#pragma once
// Whole-buffer gzip compression (libdeflate): the same deflate stream format as zlib's, at about a
// quarter of zlib's time for the same size (a 16 MB float volume: 0.075 s against 0.28 s at level
// 6 on the reference machine), for the compressed volumes every update writes.
#include <cstdint>
#include <filesystem>

namespace brainshift {

/// Compresses the file `source` into the gzip file `destination` (one gzip member, as gzip(1)
/// writes it). `expectedBytes`: how long `source` must be (a writer that stopped short is caught
/// here, not after the rename). Errors are MethodError naming `target`, the file the caller is
/// writing.
void gzipFile(const std::filesystem::path& source, const std::filesystem::path& destination, std::uint64_t expectedBytes,
              const std::filesystem::path& target, int level = 6);

} // namespace brainshift
