#pragma once
// The ways a BrainShift operation can fail; the command line maps them to exit codes
// (../shared/CONTRACT.md): bad input 2, a failure of the method 1. A cancelled operation (the
// host's Cancel) is neither.
#include <atomic>
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

/// The caller asked the operation to stop (a Cancel in the host); nothing was produced.
class CancelledError : public std::runtime_error {
public:
  using std::runtime_error::runtime_error;
};

/// A cancellation request shared with long operations: they poll it at safe points and throw
/// CancelledError naming what stopped. Null: not cancellable.
using CancelFlag = const std::atomic<bool>*;

/// Throws CancelledError("<what> cancelled") when `flag` is set.
inline void throwIfCancelled(CancelFlag flag, const char* what)
{
  if (flag && flag->load(std::memory_order_relaxed)) throw CancelledError(std::string(what) + " cancelled");
}

/// Non-fatal findings collected while reading or computing (they end up in report.json).
using Warnings = std::vector<std::string>;

/// Appends to `warnings`, or prints to stderr when no list was given.
void warn(Warnings* warnings, const std::string& message);

} // namespace brainshift
