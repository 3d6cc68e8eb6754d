#include "ModuleLoader.h"

#include <QCoreApplication>
#include <QDir>
#include <QLibrary>
#include <QPluginLoader>

#include <algorithm>

namespace brainshift {

QString defaultModulesFolder()
{
  const QByteArray fromEnvironment = qgetenv("BRAINSHIFT_MODULES_DIR");
  if (!fromEnvironment.isEmpty()) return QString::fromLocal8Bit(fromEnvironment);
  return QDir(QCoreApplication::applicationDirPath()).absoluteFilePath("../lib/brainshift-modules");
}

ModuleDiscovery discoverModules(const QString& folder)
{
  ModuleDiscovery discovery;
  const QDir directory(folder);
  if (!directory.exists()) {
    discovery.failures.push_back({folder, QObject::tr("the modules folder does not exist")});
    return discovery;
  }
  for (const QString& name : directory.entryList(QDir::Files, QDir::Name)) {
    const QString file = directory.absoluteFilePath(name);
    if (!QLibrary::isLibrary(file)) continue;
    QPluginLoader loader(file);
    QObject* instance = loader.instance();
    if (!instance) {
      discovery.failures.push_back({file, loader.errorString()});
      continue;
    }
    auto* plugin = qobject_cast<ModulePlugin*>(instance);
    if (!plugin) {
      discovery.failures.push_back({file, QObject::tr("a Qt plugin but not a BrainShift module (no %1 interface)").arg(BrainShiftModulePlugin_iid)});
      loader.unload();
      continue;
    }
    discovery.modules.push_back({file, plugin});
  }
  // The update's order, not the files' names: the surgeon's module first, then the stages.
  std::stable_sort(discovery.modules.begin(), discovery.modules.end(), [](const LoadedModule& a, const LoadedModule& b) {
    const int positionA = a.plugin->modulePosition(), positionB = b.plugin->modulePosition();
    if (positionA != positionB) return positionA < positionB;
    return a.plugin->moduleTitle().localeAwareCompare(b.plugin->moduleTitle()) < 0;
  });
  return discovery;
}

} // namespace brainshift
