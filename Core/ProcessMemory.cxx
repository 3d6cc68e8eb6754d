#include "ProcessMemory.h"

#include <cstdlib>
#include <fstream>
#include <limits>
#include <string>

#include <unistd.h>

#if defined(__linux__) && defined(__GLIBC__)
#include <malloc.h>
#endif

namespace brainshift {

namespace {
/// "always" or "madvise" (the kernel's policy in brackets): malloc's madvise has an effect.
bool transparentHugePagesAvailable()
{
  std::ifstream policy("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string line;
  if (!std::getline(policy, line)) return false;
  return line.find("[always]") != std::string::npos || line.find("[madvise]") != std::string::npos;
}

/// The value of glibc.malloc.hugetlb in GLIBC_TUNABLES ("" when it is not there).
std::string hugeTlbTunable(const std::string& tunables)
{
  const std::string key = "glibc.malloc.hugetlb=";
  const std::size_t at = tunables.find(key);
  if (at == std::string::npos) return "";
  const std::size_t end = tunables.find(':', at);
  return tunables.substr(at + key.size(), end == std::string::npos ? std::string::npos : end - at - key.size());
}
} // namespace

bool hugePageAllocations()
{
#if defined(__linux__) && defined(__GLIBC__)
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  const std::string value = hugeTlbTunable(tunables ? tunables : "");
  // 1: transparent huge pages (madvise), what restartWithHugePageAllocations sets. Not 2, whose
  // hugetlbfs pages glibc falls back from silently when none are reserved.
  return value == "1" && transparentHugePagesAvailable();
#else
  return false;
#endif
}

void restartWithHugePageAllocations(char** argv)
{
#if defined(__linux__) && defined(__GLIBC__)
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  const std::string current = tunables ? tunables : "";
  if (current.find("glibc.malloc.hugetlb") != std::string::npos) return; // set: by us, or the user's choice
  if (!transparentHugePagesAvailable()) return;
  const std::string wanted = current.empty() ? "glibc.malloc.hugetlb=1" : current + ":glibc.malloc.hugetlb=1";
  if (setenv("GLIBC_TUNABLES", wanted.c_str(), 1) != 0) return;
  execv("/proc/self/exe", argv);
  // Not executed again (no /proc, say): run on with 4 KiB pages, and leave the environment as it was.
  if (tunables) {
    setenv("GLIBC_TUNABLES", current.c_str(), 1);
  } else {
    unsetenv("GLIBC_TUNABLES");
  }
#else
  (void)argv;
#endif
}

void keepFreedMemoryForReuse()
{
#if defined(__linux__) && defined(__GLIBC__)
  mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024);
  mallopt(M_TRIM_THRESHOLD, std::numeric_limits<int>::max()); // 2 GiB, mallopt's largest
#endif
}

} // namespace brainshift
