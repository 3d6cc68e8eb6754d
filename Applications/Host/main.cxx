// brainshift-host: the BrainShift workstation.
//   brainshift-host [--module TITLE] [--screenshot FILE.png] [VOLUME | SCENE.mrml ...]
// opens the volumes and scenes given, shows the module TITLE, and with --screenshot saves the
// whole window as an image and exits (scripts/host-screenshot.sh makes the README's picture).
#include "HostMainWindow.h"
#include "VolumeIO.h"

#include <QVTKOpenGLNativeWidget.h>

#include <QApplication>
#include <QCommandLineParser>
#include <QSurfaceFormat>
#include <QTimer>

#include <cstdio>

int main(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  QApplication::setApplicationName("BrainShift");
  QCommandLineParser parser;
  parser.setApplicationDescription("The BrainShift workstation");
  parser.addHelpOption();
  const QCommandLineOption module("module", "Show this module's panel.", "title");
  const QCommandLineOption screenshot("screenshot", "Save the window as this image and exit.", "file");
  parser.addOption(module);
  parser.addOption(screenshot);
  parser.addPositionalArgument("files", "Volumes (NIfTI, NRRD, DICOM folders) and .mrml scenes to open.", "[files...]");
  parser.process(application);

  brainshift::registerIOFactories();
  brainshift::HostMainWindow window(brainshift::defaultModulesFolder());
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
  if (parser.isSet(screenshot)) {
    // Once the window is on screen and its views have rendered.
    QTimer::singleShot(1000, &window, [&] {
      const bool saved = window.grab().save(parser.value(screenshot));
      if (!saved) std::fprintf(stderr, "brainshift-host: cannot write %s\n", qPrintable(parser.value(screenshot)));
      application.exit(saved && loaded ? 0 : 1);
    });
  }
  return application.exec();
}
