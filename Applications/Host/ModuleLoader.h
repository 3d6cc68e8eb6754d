#pragma once
// Finding the modules: every shared library in the modules folder is loaded as a Qt plugin and
// kept if it implements ModulePlugin. What fails is reported, never fatal.
#include "ModulePlugin.h"

#include <QString>

#include <vector>

namespace brainshift {

struct LoadedModule {
  QString file;
  ModulePlugin* plugin; ///< owned by Qt's plugin loader, alive until the program ends
};

struct ModuleLoadFailure {
  QString file;
  QString reason;
};

struct ModuleDiscovery {
  std::vector<LoadedModule> modules;     ///< by ModulePlugin::modulePosition, then by title
  std::vector<ModuleLoadFailure> failures;
};

/// The modules folder: $BRAINSHIFT_MODULES_DIR if set, else ../lib/brainshift-modules beside the
/// executable's folder (the build tree's layout).
QString defaultModulesFolder();

/// Loads every module of `folder`. A missing folder is one failure.
ModuleDiscovery discoverModules(const QString& folder);

} // namespace brainshift
