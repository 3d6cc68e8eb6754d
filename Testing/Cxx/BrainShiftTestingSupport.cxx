#include "BrainShiftTestingSupport.h"

#include <cstdlib>

namespace brainshift::testing {
namespace fs = std::filesystem;

void fail(const char* file, int line, const std::string& message)
{
  std::ostringstream where;
  where << file << ":" << line << ": " << message;
  throw CheckFailure(where.str());
}

int runTest(const char* name, const std::function<void()>& body)
{
  try {
    body();
  } catch (const CheckFailure& failure) {
    std::cerr << name << " FAILED\n  " << failure.what() << '\n';
    return EXIT_FAILURE;
  } catch (const std::exception& e) {
    std::cerr << name << " FAILED with an unexpected exception: " << e.what() << '\n';
    return EXIT_FAILURE;
  }
  std::cout << name << " passed\n";
  return EXIT_SUCCESS;
}

fs::path temporaryFolder(const std::string& testName)
{
  const char* root = std::getenv("BRAINSHIFT_TEST_TEMP");
  fs::path folder = fs::path(root ? root : fs::temp_directory_path().string()) / testName;
  fs::remove_all(folder);
  fs::create_directories(folder);
  return folder;
}

fs::path colin27Path(const std::string& fileName)
{
  const fs::path path = fs::path("/usr/share/mricron/templates") / fileName;
  return fs::exists(path) ? path : fs::path();
}

} // namespace brainshift::testing
