// brainshift: the command line of the intraoperative update. Exit status 0 on success, 2 on bad
// usage or bad input, 1 on a failure of the method; one line on stderr says why.
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "LibraryDiagnostics.h"
#include "LibraryMessages.h"
#include "ProcessMemory.h"
#include "SignalHandling.h"

#include <itkMacro.h>

#include <iostream>
#include <string>

namespace {
/// Exactly one line on stderr per error: a message that quotes a file's content (a CSV field, a
/// scene attribute) may carry line breaks and control characters of its own.
std::string singleLine(const std::string& message)
{
  std::string line;
  for (char c : message) line += (c == '\n' || c == '\r' || c == '\v' || c == '\f') ? ' ' : c;
  while (!line.empty() && line.back() == ' ') line.pop_back();
  return line;
}
} // namespace

int main(int argc, char** argv)
{
  brainshift::restartWithHugePageAllocations(argv); // first: it may run the program again
  brainshift::keepFreedMemoryForReuse();
  brainshift::cli::installSignalHandling(); // before any thread: signals end the run cleanly (128 + signal)
  brainshift::cli::silenceLibraryDiagnostics(); // one line per error: ours, naming the file
  CLI::App app{"BrainShift: biomechanical simulation of brain shift for image-guided neurosurgery.\n"
               "Brings preoperative MRI, fMRI and segmentations into the brain's shape on each intraoperative MRI.",
               "brainshift"};
  app.set_version_flag("--version", std::string("brainshift 0.1.0"));
  app.require_subcommand(1);
  brainshift::cli::addDemoCommand(app);
  brainshift::cli::addRegisterCommand(app);
  brainshift::cli::addWatchCommand(app);
  brainshift::cli::addStageCommands(app);
  brainshift::cli::addEvaluateCommand(app);
  brainshift::cli::addBenchCommand(app);
  brainshift::cli::addSendCommand(app);
  brainshift::cli::addExportDicomCommand(app);

  std::string command = "brainshift";
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << "brainshift: " << e.what() << " (see brainshift --help)\n";
    return 2;
  } catch (const brainshift::InputError& e) {
    std::cerr << "brainshift: " << singleLine(e.what()) << '\n';
    return 2;
  } catch (const brainshift::MethodError& e) {
    std::cerr << "brainshift: " << singleLine(e.what()) << '\n';
    return 1;
  } catch (const itk::ExceptionObject& e) { // its what() starts with the source file's path on a line of its own
    std::cerr << "brainshift: internal error: " << brainshift::oneLine(e.GetDescription()) << '\n';
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "brainshift: internal error: " << singleLine(e.what()) << '\n';
    return 1;
  }
  return 0;
}
