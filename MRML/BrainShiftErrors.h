#pragma once
// The three ways a BrainShift operation can fail; the command line maps them to exit codes
// (../shared/CONTRACT.md): bad input 2, a failure of the method 1.
#include <stdexcept>
#include <string>
#include <vector>

namespace brainshift {

/// The input is wrong: a missing, unreadable or corrupt file, mismatched geometry, an absurd
/// option. The message names the file (or option) and the problem.
class InputError : public std::runtime_error {
public:
  using std::runtime_error::runtime_error;
};

/// The method itself failed on valid input: no convergence, a result that cannot be trusted,
/// a worker that died.
class MethodError : public std::runtime_error {
public:
  using std::runtime_error::runtime_error;
};

/// A stage of the method that this build does not provide yet.
class NotAvailableError : public MethodError {
public:
  using MethodError::MethodError;
};

/// Non-fatal findings collected while reading or computing (they end up in report.json).
using Warnings = std::vector<std::string>;

/// Appends to `warnings`, or prints to stderr when no list was given.
void warn(Warnings* warnings, const std::string& message);

} // namespace brainshift
