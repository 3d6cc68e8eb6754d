#include "HostMainWindow.h"

#include <QAction>
#include <QActionGroup>
#include <QCheckBox>
#include <QComboBox>
#include <QFileDialog>
#include <QFileInfo>
#include <QMenuBar>
#include <QMessageBox>
#include <QScrollArea>
#include <QSplitter>
#include <QStackedWidget>
#include <QStatusBar>
#include <QTimer>
#include <QVBoxLayout>

namespace brainshift {

HostMainWindow::HostMainWindow(const QString& modulesFolder, const QString& configurationFile, QWidget* parent)
  : QMainWindow(parent)
{
  setWindowTitle(tr("BrainShift"));
  views_ = new ViewLayout(this);
  auto* left = new QWidget(this);
  moduleSelector_ = new QComboBox(left);
  moduleSelector_->setObjectName("moduleSelector");
  panels_ = new QStackedWidget(left);
  auto* leftColumn = new QVBoxLayout(left);
  leftColumn->addWidget(moduleSelector_);
  leftColumn->addWidget(panels_, 1);
  auto* splitter = new QSplitter(this);
  splitter->addWidget(left);
  splitter->addWidget(views_);
  splitter->setStretchFactor(0, 0);
  splitter->setStretchFactor(1, 1);
  splitter->setSizes({390, 890});
  setCentralWidget(splitter);

  dataPanel_ = new DataPanel(scene_, *views_, panels_);
  moduleSelector_->addItem(tr("Data"));
  panels_->addWidget(dataPanel_);
  addModules(modulesFolder, configurationFile);
  connect(moduleSelector_, qOverload<int>(&QComboBox::currentIndexChanged), panels_, &QStackedWidget::setCurrentIndex);

  // Models shown in 3D follow the scene; the update waits for the event loop so that a scene
  // read adding many nodes updates the view once.
  sceneObserver_ = scene_.addObserver([this](const SceneEvent& event) {
    if (event.node->kind() != NodeKind::Model || threeDUpdatePending_) return;
    threeDUpdatePending_ = true;
    QTimer::singleShot(0, this, [this] {
      threeDUpdatePending_ = false;
      updateThreeDView();
    });
  });
  buildMenus();
  resize(1280, 800);
}

HostMainWindow::~HostMainWindow()
{
  scene_.removeObserver(sceneObserver_);
  // The panels follow the scene; they go before it does.
  delete centralWidget();
}

void HostMainWindow::addModules(const QString& modulesFolder, const QString& configurationFile)
{
  ModuleDiscovery discovery = discoverModules(modulesFolder);
  moduleFailures_ = discovery.failures;
  ModuleContext context;
  context.configurationFile = configurationFile.toStdString();
  context.showPoint = [this](const std::array<double, 3>& lps) {
    PhysicalPoint p;
    for (int i = 0; i < 3; ++i) p[i] = lps[i];
    views_->setCursorPosition(p);
  };
  context.subscribeToPicks = [this](QObject* receiver, std::function<void(const std::array<double, 3>&)> onPick) {
    connect(views_, &ViewLayout::pointPicked, receiver, [onPick](const PhysicalPoint& p) { onPick({p[0], p[1], p[2]}); });
  };
  context.showLayers = [this](const ViewLayers& layers) {
    // Through the Data panel's selectors, so that it shows what the views show.
    dataPanel_->backgroundSelector()->setCurrentNodeId(QString::fromStdString(layers.backgroundId));
    dataPanel_->labelMapSelector()->setCurrentNodeId(QString::fromStdString(layers.labelMapId));
    dataPanel_->overlaySelector()->setCurrentNodeId(QString::fromStdString(layers.overlayId));
    dataPanel_->comparisonSelector()->setCurrentNodeId(QString::fromStdString(layers.comparisonId));
    dataPanel_->comparisonModeBox()->setCurrentIndex(layers.comparisonMode);
    dataPanel_->labelOutlineBox()->setChecked(layers.labelOutline);
    views_->updateLayers();
  };
  for (const LoadedModule& module : discovery.modules) {
    const QString title = module.plugin->moduleTitle();
    try {
      QWidget* panel = module.plugin->createPanel(scene_, context, panels_);
      if (!panel) throw std::runtime_error("the module made no panel");
      auto* scroll = new QScrollArea(panels_);
      scroll->setWidgetResizable(true);
      scroll->setWidget(panel);
      panels_->addWidget(scroll);
      moduleSelector_->addItem(title);
    } catch (const std::exception& e) {
      moduleFailures_.push_back({module.file, tr("%1: %2").arg(title, QString::fromStdString(e.what()))});
    }
  }
  showModuleFailures();
}

void HostMainWindow::showModuleFailures()
{
  if (moduleFailures_.empty()) {
    const int loaded = moduleSelector_->count() - 1;
    lastMessage_ = tr("%1 module%2 loaded").arg(loaded).arg(loaded == 1 ? "" : "s");
  } else {
    QStringList lines;
    for (const ModuleLoadFailure& failure : moduleFailures_) lines << tr("%1: %2").arg(failure.file, failure.reason);
    const int failed = int(moduleFailures_.size());
    lastMessage_ = tr("%1 module%2 could not be loaded: ").arg(failed).arg(failed == 1 ? "" : "s") + lines.join("; ");
    for (const QString& line : lines) qWarning("brainshift-host: module not loaded: %s", qPrintable(line));
  }
  statusBar()->showMessage(lastMessage_);
}

QStringList HostMainWindow::moduleTitles() const
{
  QStringList titles;
  for (int i = 0; i < moduleSelector_->count(); ++i) titles << moduleSelector_->itemText(i);
  return titles;
}

bool HostMainWindow::selectModule(const QString& title)
{
  const int index = moduleSelector_->findText(title);
  if (index < 0) return false;
  moduleSelector_->setCurrentIndex(index);
  return true;
}

QWidget* HostMainWindow::currentPanel() const
{
  QWidget* page = panels_->currentWidget();
  if (auto* scroll = qobject_cast<QScrollArea*>(page)) return scroll->widget();
  return page;
}

QString HostMainWindow::report(const LoadResult& result, const QString& success)
{
  lastMessage_ = result ? success : result.error;
  statusBar()->showMessage(lastMessage_);
  return result.error;
}

QString HostMainWindow::loadVolume(const QString& path)
{
  const LoadResult result = brainshift::loadScalarVolume(scene_, path);
  if (result) dataPanel_->backgroundSelector()->setCurrentNodeId(QString::fromStdString(result.node->id()));
  return report(result, tr("Loaded the volume %1").arg(path));
}

QString HostMainWindow::loadLabelMap(const QString& path)
{
  const LoadResult result = brainshift::loadLabelMap(scene_, path);
  if (result) dataPanel_->labelMapSelector()->setCurrentNodeId(QString::fromStdString(result.node->id()));
  return report(result, tr("Loaded the label map %1").arg(path));
}

QString HostMainWindow::loadOverlay(const QString& path)
{
  const LoadResult result = brainshift::loadOverlay(scene_, path);
  if (result) dataPanel_->overlaySelector()->setCurrentNodeId(QString::fromStdString(result.node->id()));
  return report(result, tr("Loaded the overlay %1").arg(path));
}

QString HostMainWindow::loadScene(const QString& path)
{
  const LoadResult result = brainshift::loadScene(scene_, path);
  if (result) {
    // The intraoperative scan is the natural background of a BrainShift scene.
    for (const auto& volume : scene_.nodesOfType<ScalarVolumeNode>()) {
      if (volume->role() == "intraop") dataPanel_->backgroundSelector()->setCurrentNodeId(QString::fromStdString(volume->id()));
    }
  }
  return report(result, tr("Loaded the scene %1").arg(path));
}

QString HostMainWindow::saveScene(const QString& path)
{
  return report(brainshift::saveScene(scene_, path), tr("Saved the scene %1").arg(path));
}

void HostMainWindow::updateThreeDView()
{
  // Models under transforms (the brain surface under the rigid transform) in the world frame.
  views_->threeDView()->setModels(scene_.nodesOfType<ModelNode>(),
                                  [this](const ModelNode& model) { return childToWorldMatrix(scene_, model); });
  if (!views_->threeDView()->problems().isEmpty()) statusBar()->showMessage(views_->threeDView()->problems().join("; "));
}

void HostMainWindow::runFileDialog(const QString& title, const QString& filter, QString (HostMainWindow::*load)(const QString&))
{
  const QString path = QFileDialog::getOpenFileName(this, title, QString(), filter);
  if (path.isEmpty()) return;
  const QString error = (this->*load)(path);
  if (!error.isEmpty()) QMessageBox::warning(this, title, error);
}

void HostMainWindow::buildMenus()
{
  const QString volumes = tr("Volumes (*.nii *.nii.gz *.nrrd *.nhdr *.mha *.mhd);;All files (*)");
  QMenu* file = menuBar()->addMenu(tr("&File"));
  file->addAction(tr("Load &volume..."), this, [this, volumes] { runFileDialog(tr("Load volume"), volumes, &HostMainWindow::loadVolume); });
  file->addAction(tr("Load &label map..."), this, [this, volumes] { runFileDialog(tr("Load label map"), volumes, &HostMainWindow::loadLabelMap); });
  file->addAction(tr("Load &overlay..."), this, [this, volumes] { runFileDialog(tr("Load overlay"), volumes, &HostMainWindow::loadOverlay); });
  file->addAction(tr("Load DICOM &series..."), this, [this] {
    const QString folder = QFileDialog::getExistingDirectory(this, tr("Load DICOM series"));
    if (folder.isEmpty()) return;
    const QString error = loadVolume(folder);
    if (!error.isEmpty()) QMessageBox::warning(this, tr("Load DICOM series"), error);
  });
  file->addSeparator();
  file->addAction(tr("Load &scene..."), this, [this] { runFileDialog(tr("Load scene"), tr("Scenes (*.mrml)"), &HostMainWindow::loadScene); });
  file->addAction(tr("Sa&ve scene..."), this, [this] {
    const QString path = QFileDialog::getSaveFileName(this, tr("Save scene"), "scene.mrml", tr("Scenes (*.mrml)"));
    if (path.isEmpty()) return;
    const QString error = saveScene(path);
    if (!error.isEmpty()) QMessageBox::warning(this, tr("Save scene"), error);
  });
  file->addSeparator();
  file->addAction(tr("&Quit"), this, &QWidget::close);

  QMenu* view = menuBar()->addMenu(tr("&View"));
  auto* layouts = new QActionGroup(this);
  const std::pair<QString, ViewArrangement> arrangements[] = {
    {tr("Four-up"), ViewArrangement::FourUp},         {tr("Axial only"), ViewArrangement::OneUpAxial},
    {tr("Sagittal only"), ViewArrangement::OneUpSagittal}, {tr("Coronal only"), ViewArrangement::OneUpCoronal},
    {tr("3D only"), ViewArrangement::OneUp3D}};
  for (const auto& [text, arrangement] : arrangements) {
    QAction* action = view->addAction(text, this, [this, arrangement = arrangement] { views_->setArrangement(arrangement); });
    action->setCheckable(true);
    action->setChecked(arrangement == ViewArrangement::FourUp);
    layouts->addAction(action);
  }
  view->addSeparator();
  QAction* arrows = view->addAction(tr("Displacement &arrows in 3D"), this,
                                    [this](bool on) { views_->threeDView()->setDisplacementArrowsVisible(on); });
  arrows->setCheckable(true);
  arrows->setObjectName("arrowsAction");
  QAction* planes = view->addAction(tr("Slice &planes in 3D"), this,
                                    [this](bool on) { views_->threeDView()->setSlicePlanesVisible(on); });
  planes->setCheckable(true);
  planes->setObjectName("slicePlanesAction");

  QMenu* help = menuBar()->addMenu(tr("&Help"));
  help->addAction(tr("&Modules..."), this, [this] {
    QString text = tr("Loaded: %1").arg(moduleTitles().mid(1).join(", "));
    for (const ModuleLoadFailure& failure : moduleFailures_) text += "\n" + tr("Not loaded: %1: %2").arg(failure.file, failure.reason);
    QMessageBox::information(this, tr("Modules"), text);
  });
}

} // namespace brainshift
