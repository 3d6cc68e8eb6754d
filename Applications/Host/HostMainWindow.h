#pragma once
// The host's main window: the module selector and the chosen module's panel on the left, the
// views on the right, the scene, and the File menu (volumes, label maps, overlays, .mrml
// scenes). Loads never lose what is loaded: a bad file leaves a message and the scene as it was.
#include "DataPanel.h"
#include "ModuleLoader.h"
#include "SceneLoading.h"
#include "ViewLayout.h"

#include <QMainWindow>

class QComboBox;
class QStackedWidget;

namespace brainshift {

class HostMainWindow : public QMainWindow {
  Q_OBJECT
public:
  /// Loads the modules of `modulesFolder` (see defaultModulesFolder()); their panels take their
  /// defaults from `configurationFile` (empty: the product's; ModuleContext::configurationFile).
  explicit HostMainWindow(const QString& modulesFolder, const QString& configurationFile = {}, QWidget* parent = nullptr);
  ~HostMainWindow() override;

  Scene& scene() { return scene_; }
  ViewLayout* views() const { return views_; }
  DataPanel* dataPanel() const { return dataPanel_; }

  /// The titles in the module selector: "Data" first, then the loaded modules.
  QStringList moduleTitles() const;
  const std::vector<ModuleLoadFailure>& moduleFailures() const { return moduleFailures_; }
  /// Shows the panel of the module with this title; false if there is none.
  bool selectModule(const QString& title);
  QWidget* currentPanel() const;

  /// The File menu's loads and save without their dialogs: an empty string on success, else the
  /// message the window shows (in the status bar; the menu actions also show a message box).
  QString loadVolume(const QString& path);
  QString loadLabelMap(const QString& path);
  QString loadOverlay(const QString& path);
  QString loadScene(const QString& path);
  QString saveScene(const QString& path);
  /// The last message of a load or save (or of the module loading at start).
  QString lastMessage() const { return lastMessage_; }

private:
  void buildMenus();
  void addModules(const QString& modulesFolder, const QString& configurationFile);
  QString report(const LoadResult& result, const QString& success);
  void runFileDialog(const QString& title, const QString& filter, QString (HostMainWindow::*load)(const QString&));
  void updateThreeDView();
  void showModuleFailures();

  Scene scene_;
  Scene::ObserverId sceneObserver_ = 0;
  bool threeDUpdatePending_ = false;
  ViewLayout* views_;
  DataPanel* dataPanel_;
  QComboBox* moduleSelector_;
  QStackedWidget* panels_;
  std::vector<ModuleLoadFailure> moduleFailures_;
  QString lastMessage_;
};

} // namespace brainshift
