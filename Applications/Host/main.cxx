// brainshift-host: the BrainShift workstation. Arguments: volumes or .mrml scenes to open.
#include "HostMainWindow.h"
#include "VolumeIO.h"

#include <QVTKOpenGLNativeWidget.h>

#include <QApplication>
#include <QSurfaceFormat>

#include <cstdio>

int main(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  QApplication::setApplicationName("BrainShift");
  brainshift::registerIOFactories();
  brainshift::HostMainWindow window(brainshift::defaultModulesFolder());
  for (const QString& argument : QApplication::arguments().mid(1)) {
    const QString error = argument.endsWith(".mrml") ? window.loadScene(argument) : window.loadVolume(argument);
    if (!error.isEmpty()) std::fprintf(stderr, "brainshift-host: %s\n", qPrintable(error));
  }
  window.show();
  return application.exec();
}
