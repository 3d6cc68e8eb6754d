#include "SignalHandling.h"

#include "ProcessCleanup.h"

#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <thread>
#include <unistd.h>

namespace brainshift::cli {

namespace {
int signalPipe[2] = {-1, -1};
std::atomic<bool> endingOnSignal{false};
int stderrCopy = -1; ///< taken at start: a writer may have muted stderr when the signal comes

const char* nameOf(int number)
{
  switch (number) {
  case SIGINT: return "SIGINT";
  case SIGTERM: return "SIGTERM";
  case SIGHUP: return "SIGHUP";
  default: return "a signal";
  }
}

/// Async-signal-safe: hands the signal's number to the cleanup thread.
void onSignal(int number)
{
  const unsigned char byte = static_cast<unsigned char>(number);
  const int saved = errno;
  [[maybe_unused]] const ssize_t written = ::write(signalPipe[1], &byte, 1);
  errno = saved;
}

/// Waits for a signal, then ends the run: workers, temporary files, one line, 128 + signal. It
/// runs in an ordinary thread, so it may use the file system; the main thread, should it reach its
/// own end meanwhile, is held in its exit handler (below) until this thread has exited.
void cleanupThread()
{
  unsigned char number = 0;
  while (::read(signalPipe[0], &number, 1) != 1) {
  }
  endingOnSignal = true;
  // The main thread's own report of what the signal interrupted ("the worker died") is not the
  // error: its stderr goes to /dev/null, this thread's line to the real one.
  const int null = ::open("/dev/null", O_WRONLY | O_CLOEXEC);
  if (null >= 0) ::dup2(null, STDERR_FILENO);
  brainshift::cleanup::terminateAndRemoveAll(3.0);
  char line[128];
  const int length = std::snprintf(line, sizeof line, "brainshift: stopped by %s; worker processes and temporary files removed\n",
                                   nameOf(number));
  [[maybe_unused]] const ssize_t written = ::write(stderrCopy >= 0 ? stderrCopy : STDERR_FILENO, line, std::size_t(length));
  ::_exit(128 + number);
}
} // namespace

void installSignalHandling()
{
  ::signal(SIGXFSZ, SIG_IGN); // a write past `ulimit -f` fails with EFBIG and is reported
  if (::pipe2(signalPipe, O_CLOEXEC) != 0) return;
  stderrCopy = ::fcntl(STDERR_FILENO, F_DUPFD_CLOEXEC, 3);
  std::thread(cleanupThread).detach();
  struct sigaction action {};
  action.sa_handler = onSignal;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;
  for (int number : {SIGINT, SIGTERM, SIGHUP}) ::sigaction(number, &action, nullptr);
  // The main thread must not exit with its own status while the cleanup thread works.
  std::atexit([] {
    while (endingOnSignal) ::pause();
  });
}

} // namespace brainshift::cli
