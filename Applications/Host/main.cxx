// brainshift-host: the BrainShift workstation.
//   brainshift-host [--config FILE.json] [--module TITLE] [--screenshot FILE.png] [VOLUME | SCENE.mrml ...]
//   brainshift-host --preop-image F --preop-labels F [--overlay NAME=F ...] --session-dir DIR
//                   [--replace-session] [--scan F ...] [--screenshot FILE.png]
// opens the volumes and scenes given, shows the module TITLE, and with --screenshot saves the
// whole window as an image and exits (scripts/host-screenshot.sh makes the README's pictures).
// The second form opens the "Intraoperative update" module on a case, prepares it and updates it
// with each --scan in turn, as the surgeon would; --screenshot then waits for the last scan.
#include "Configuration.h"
#include "HostMainWindow.h"
#include "ProcessMemory.h"
#include "ScriptedSession.h"
#include "VolumeIO.h"

#include <QVTKOpenGLNativeWidget.h>

#include <QApplication>
#include <QCommandLineParser>
#include <QSurfaceFormat>
#include <QTimer>

#include <cstdio>
#include <functional>

namespace {
/// Saves the window once its views have rendered, and ends the application (1 when `ok` is false).
void saveScreenshot(QWidget& window, const QString& file, bool ok)
{
  QTimer::singleShot(1500, &window, [&window, file, ok] {
    const bool saved = window.grab().save(file);
    if (!saved) std::fprintf(stderr, "brainshift-host: cannot write %s\n", qPrintable(file));
    QApplication::exit(saved && ok ? 0 : 1);
  });
}

/// The Intraoperative update module on a case (ScriptedSession.h); false when it is not loaded.
bool startSession(brainshift::HostMainWindow& window, const QString& preopImage, const QString& preopLabels,
                  const QStringList& overlays, const QString& folder, const QString& configuration, bool replace,
                  const QStringList& scans, std::function<void(bool)> done)
{
  if (!window.selectModule("Intraoperative update")) {
    std::fprintf(stderr, "brainshift-host: the Intraoperative update module is not loaded\n");
    return false;
  }
  QWidget* panel = window.currentPanel();
  QMetaObject::invokeMethod(panel, "setCase", Q_ARG(QString, preopImage), Q_ARG(QString, preopLabels), Q_ARG(QStringList, overlays),
                            Q_ARG(QString, folder), Q_ARG(QString, configuration));
  QMetaObject::invokeMethod(panel, "setReplaceEarlierSession", Q_ARG(bool, replace));
  new brainshift::ScriptedSession(panel, scans, std::move(done)); // owned by the panel
  QMetaObject::invokeMethod(panel, "prepareCase");
  return true;
}
} // namespace

int main(int argc, char* argv[])
{
  brainshift::restartWithHugePageAllocations(argv); // first: it may run the program again
  brainshift::keepFreedMemoryForReuse();
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  QApplication::setApplicationName("BrainShift");
  QCommandLineParser parser;
  parser.setApplicationDescription("The BrainShift workstation");
  parser.addHelpOption();
  const QCommandLineOption module("module", "Show this module's panel.", "title");
  const QCommandLineOption screenshot("screenshot", "Save the window as this image and exit.", "file");
  const QCommandLineOption preopImage("preop-image", "Intraoperative update: the preoperative MRI.", "file");
  const QCommandLineOption preopLabels("preop-labels", "Intraoperative update: the preoperative labels.", "file");
  const QCommandLineOption overlay("overlay", "Intraoperative update: NAME=FILE, a preoperative overlay (repeatable).", "name=file");
  const QCommandLineOption sessionDir("session-dir", "Intraoperative update: the session's folder.", "folder");
  const QCommandLineOption replaceSession("replace-session", "Intraoperative update: replace an earlier session in the folder.");
  const QCommandLineOption scan("scan", "Intraoperative update: a scan to update with (repeatable, in order).", "file");
  const QCommandLineOption config("config", "The JSON configuration of `brainshift register --config`: every panel's defaults.", "file");
  for (const QCommandLineOption* option : {&module, &screenshot, &preopImage, &preopLabels, &overlay, &sessionDir, &replaceSession, &scan, &config}) {
    parser.addOption(*option);
  }
  parser.addPositionalArgument("files", "Volumes (NIfTI, NRRD, DICOM folders) and .mrml scenes to open.", "[files...]");
  parser.process(application);

  brainshift::registerIOFactories();
  if (parser.isSet(config)) { // checked once here: the panels read it without a word
    try {
      brainshift::Configuration::load(parser.value(config).toStdString());
    } catch (const std::exception& e) {
      std::fprintf(stderr, "brainshift-host: %s\n", e.what());
      return 2;
    }
  }
  brainshift::HostMainWindow window(brainshift::defaultModulesFolder(), parser.value(config));
  bool loaded = true;
  for (const QString& file : parser.positionalArguments()) {
    const QString error = file.endsWith(".mrml") ? window.loadScene(file) : window.loadVolume(file);
    if (!error.isEmpty()) {
      std::fprintf(stderr, "brainshift-host: %s\n", qPrintable(error));
      loaded = false;
    }
  }
  if (parser.isSet(module) && !window.selectModule(parser.value(module))) {
    std::fprintf(stderr, "brainshift-host: no module '%s'\n", qPrintable(parser.value(module)));
    loaded = false;
  }
  window.show();
  const bool session = parser.isSet(preopImage);
  if (session && !startSession(window, parser.value(preopImage), parser.value(preopLabels), parser.values(overlay),
                               parser.value(sessionDir), parser.value(config), parser.isSet(replaceSession), parser.values(scan),
                               [&](bool ok) {
                                 loaded = loaded && ok;
                                 if (parser.isSet(screenshot)) saveScreenshot(window, parser.value(screenshot), loaded);
                               })) {
    return 2;
  }
  if (parser.isSet(screenshot) && !session) {
    // Once the window is on screen and its views have rendered.
    QTimer::singleShot(1000, &window, [&] {
      const bool saved = window.grab().save(parser.value(screenshot));
      if (!saved) std::fprintf(stderr, "brainshift-host: cannot write %s\n", qPrintable(parser.value(screenshot)));
      application.exit(saved && loaded ? 0 : 1);
    });
  }
  return application.exec();
}
