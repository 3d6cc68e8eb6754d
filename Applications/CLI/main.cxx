// brainshift: the command line of the intraoperative update. Exit status 0 on success, 2 on bad
// usage or bad input, 1 on a failure of the method; one line on stderr says why.
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "LibraryDiagnostics.h"
#include "SignalHandling.h"

#include <iostream>

int main(int argc, char** argv)
{
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
    std::cerr << "brainshift: " << e.what() << '\n';
    return 2;
  } catch (const brainshift::MethodError& e) {
    std::cerr << "brainshift: " << e.what() << '\n';
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "brainshift: internal error: " << e.what() << '\n';
    return 1;
  }
  return 0;
}
