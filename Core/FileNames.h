#pragma once
// File-name tests shared by the readers and writers of MRML (format by extension, any case).
#include <filesystem>
#include <initializer_list>
#include <string>

namespace brainshift {

/// The file name alone, lower case: "T1.NII.GZ" -> "t1.nii.gz".
std::string lowerCaseFileName(const std::filesystem::path& path);

/// True if the file name ends (in any case) with one of `extensions` (".nii.gz", ".tfm", ...).
bool hasExtension(const std::filesystem::path& path, std::initializer_list<const char*> extensions);

} // namespace brainshift
