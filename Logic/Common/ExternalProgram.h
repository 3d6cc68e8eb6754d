#pragma once
// Finding and calling another program (CalculiX for the built-in case's finite element truth and
// the solver's cross-check test).
#include <filesystem>
#include <string>

namespace brainshift {

/// The first executable `name` in the folders of PATH, or an empty path.
std::filesystem::path findOnPath(const std::string& name);

/// `text` in single quotes for a POSIX shell (a quote inside becomes '\'').
std::string shellQuoted(const std::string& text);

} // namespace brainshift
