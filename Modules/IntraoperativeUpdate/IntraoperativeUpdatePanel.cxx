#include "IntraoperativeUpdatePanel.h"

#include "Scene.h"
#include "SceneIO.h"
#include "UpdateFocus.h"

#include <QApplication>
#include <QCheckBox>
#include <QComboBox>
#include <QFileDialog>
#include <QFormLayout>
#include <QGroupBox>
#include <QHBoxLayout>
#include <QHeaderView>
#include <QLabel>
#include <QLineEdit>
#include <QProgressBar>
#include <QPushButton>
#include <QTableWidget>
#include <QTimer>
#include <QVBoxLayout>

#include <algorithm>
#include <cmath>

namespace brainshift {
namespace fs = std::filesystem;

/// A scan's result read aside (off the GUI thread), ready to replace the scene.
struct IntraoperativeUpdatePanel::ShownScan {
  Scene scene;
  std::optional<std::array<double, 3>> focus;
  std::string error; ///< why it could not be read; empty when it was
};

namespace {
/// Runs `call` on the GUI thread later, if the panel still exists then.
template <typename Call>
void onGuiThread(QPointer<IntraoperativeUpdatePanel> panel, Call call)
{
  QMetaObject::invokeMethod(
    qApp, [panel, call = std::move(call)]() mutable {
      if (panel) call(*panel);
    },
    Qt::QueuedConnection);
}

/// Reads a scan's scene aside: what the views will show of it.
std::shared_ptr<IntraoperativeUpdatePanel::ShownScan> readScanResult(const fs::path& scanFolder)
{
  auto shown = std::make_shared<IntraoperativeUpdatePanel::ShownScan>();
  const fs::path file = scanFolder / "scene.mrml";
  std::error_code ec;
  if (!fs::exists(file, ec)) {
    shown->error = file.string() + ": the scan wrote no scene";
    return shown;
  }
  try {
    readScene(shown->scene, file);
    shown->focus = updateFocusPoint(shown->scene);
  } catch (const std::exception& e) {
    shown->scene.clear();
    shown->error = e.what();
  }
  return shown;
}

QLineEdit* pathField(QWidget* parent, QFormLayout* form, const QString& label, bool folder, const QString& filter = QString())
{
  auto* row = new QWidget(parent);
  auto* layout = new QHBoxLayout(row);
  layout->setContentsMargins(0, 0, 0, 0);
  auto* field = new QLineEdit(row);
  auto* browse = new QPushButton(QObject::tr("Browse..."), row);
  layout->addWidget(field, 1);
  layout->addWidget(browse);
  QObject::connect(browse, &QPushButton::clicked, field, [field, folder, filter, label] {
    const QString chosen = folder ? QFileDialog::getExistingDirectory(field, label, field->text())
                                  : QFileDialog::getOpenFileName(field, label, field->text(), filter);
    if (!chosen.isEmpty()) field->setText(chosen);
  });
  form->addRow(label, row);
  return field;
}

QString imageFilter()
{
  return QObject::tr("Images (*.nii *.nii.gz *.nrrd *.nhdr *.mha *.mhd);;All files (*)");
}
} // namespace

IntraoperativeUpdatePanel::IntraoperativeUpdatePanel(Scene& scene, const ModuleContext& context, QWidget* parent)
  : QWidget(parent)
  , scene_(scene)
  , context_(context)
{
  auto* layout = new QVBoxLayout(this);
  trust_ = new QLabel(this);
  trust_->setWordWrap(true);
  trust_->setVisible(false);
  trust_->setObjectName("trustBanner");
  layout->addWidget(trust_);
  buildCaseGroup();
  buildScanGroup();
  layout->addWidget(caseGroup_);
  layout->addWidget(scanGroup_, 1);
  poll_ = new QTimer(this);
  poll_->setInterval(1000);
  connect(poll_, &QTimer::timeout, this, &IntraoperativeUpdatePanel::pollWatchedFolder);
  updateControls();
}

IntraoperativeUpdatePanel::~IntraoperativeUpdatePanel()
{
  poll_->stop();
  if (logic_ && running_) logic_->cancel();
  joinWorker(); // no update outlives the panel; what it posts back finds no panel
}

void IntraoperativeUpdatePanel::buildCaseGroup()
{
  auto* group = new QGroupBox(tr("Case (before surgery)"), this);
  auto* form = new QFormLayout(group);
  preopImage_ = pathField(group, form, tr("Preoperative MRI"), false, imageFilter());
  preopLabels_ = pathField(group, form, tr("Preoperative labels"), false, imageFilter());
  overlays_ = new QLineEdit(group);
  overlays_->setPlaceholderText(tr("NAME=FILE; ... (fMRI statistics, MRA)"));
  form->addRow(tr("Overlays"), overlays_);
  config_ = pathField(group, form, tr("Configuration (optional)"), false, tr("JSON (*.json)"));
  config_->setText(QString::fromStdString(context_.configurationFile)); // the host's, as the stage panels take it
  outputFolder_ = pathField(group, form, tr("Session folder"), true);
  replaceEarlier_ = new QCheckBox(tr("Replace an earlier session in this folder"), group);
  form->addRow(replaceEarlier_);
  prepare_ = new QPushButton(tr("Prepare case"), group);
  form->addRow(prepare_);
  connect(prepare_, &QPushButton::clicked, this, &IntraoperativeUpdatePanel::prepareCase);
  caseGroup_ = group;
}

void IntraoperativeUpdatePanel::buildScanGroup()
{
  auto* group = new QGroupBox(tr("Scans (during surgery)"), this);
  auto* layout = new QVBoxLayout(group);
  auto* form = new QFormLayout();
  watchFolder_ = pathField(group, form, tr("Scanner folder"), true);
  layout->addLayout(form);
  auto* buttons = new QHBoxLayout();
  watch_ = new QPushButton(tr("Watch folder"), group);
  watch_->setCheckable(true);
  loadScan_ = new QPushButton(tr("Load scan..."), group);
  cancel_ = new QPushButton(tr("Cancel"), group);
  for (QPushButton* b : {watch_, loadScan_, cancel_}) buttons->addWidget(b);
  layout->addLayout(buttons);
  progress_ = new QProgressBar(group);
  progress_->setRange(0, 1);
  progress_->setValue(0);
  progress_->setFormat(tr("idle"));
  status_ = new QLabel(tr("Choose the case and prepare it."), group);
  status_->setWordWrap(true);
  layout->addWidget(progress_);
  layout->addWidget(status_);
  overlayChoice_ = new QComboBox(group);
  auto* overlayForm = new QFormLayout();
  overlayForm->addRow(tr("Overlay shown"), overlayChoice_);
  layout->addLayout(overlayForm);
  scans_ = new QTableWidget(0, 5, group);
  scans_->setHorizontalHeaderLabels({tr("Scan"), tr("Seconds"), tr("Outcome"), tr("Trust"), tr("Warnings")});
  scans_->setSelectionBehavior(QAbstractItemView::SelectRows);
  scans_->setSelectionMode(QAbstractItemView::SingleSelection);
  scans_->setEditTriggers(QAbstractItemView::NoEditTriggers);
  scans_->horizontalHeader()->setSectionResizeMode(QHeaderView::ResizeToContents);
  scans_->horizontalHeader()->setStretchLastSection(true);
  scans_->verticalHeader()->setVisible(false);
  layout->addWidget(scans_, 1);
  connect(watch_, &QPushButton::toggled, this, [this](bool on) { on ? startWatching() : stopWatching(); });
  connect(loadScan_, &QPushButton::clicked, this, [this] {
    const QString file = QFileDialog::getOpenFileName(this, tr("Intraoperative scan"), watchFolder_->text(), imageFilter());
    if (!file.isEmpty()) addScan(file);
  });
  connect(cancel_, &QPushButton::clicked, this, &IntraoperativeUpdatePanel::cancel);
  connect(scans_, &QTableWidget::cellDoubleClicked, this, [this](int row, int) { showScan(row); });
  connect(overlayChoice_, QOverload<int>::of(&QComboBox::activated), this, &IntraoperativeUpdatePanel::choose);
  scanGroup_ = group;
}

void IntraoperativeUpdatePanel::setCase(const QString& preopImage, const QString& preopLabels, const QStringList& overlays,
                                        const QString& outputFolder, const QString& configFile)
{
  preopImage_->setText(preopImage);
  preopLabels_->setText(preopLabels);
  overlays_->setText(overlays.join("; "));
  outputFolder_->setText(outputFolder);
  config_->setText(configFile);
}

void IntraoperativeUpdatePanel::setReplaceEarlierSession(bool replace) { replaceEarlier_->setChecked(replace); }
void IntraoperativeUpdatePanel::setWatchFolder(const QString& folder) { watchFolder_->setText(folder); }
void IntraoperativeUpdatePanel::setPollMilliseconds(int milliseconds) { poll_->setInterval(std::max(50, milliseconds)); }
QString IntraoperativeUpdatePanel::statusText() const { return status_->text(); }
QString IntraoperativeUpdatePanel::trustText() const { return trust_->text(); }
bool IntraoperativeUpdatePanel::isPrepared() const { return logic_ && logic_->prepared(); }
bool IntraoperativeUpdatePanel::isWatching() const { return poll_->isActive(); }

RunOptions IntraoperativeUpdatePanel::caseOptions() const
{
  RunOptions options;
  options.preopImage = preopImage_->text().trimmed().toStdString();
  options.preopLabels = preopLabels_->text().trimmed().toStdString();
  options.outputDir = outputFolder_->text().trimmed().toStdString();
  options.config = config_->text().trimmed().toStdString();
  for (const QString& overlay : overlays_->text().split(';', Qt::SkipEmptyParts)) {
    if (!overlay.trimmed().isEmpty()) options.overlays.push_back(overlay.trimmed().toStdString());
  }
  options.overwrite = replaceEarlier_->isChecked();
  return options;
}

void IntraoperativeUpdatePanel::setCaseEditable(bool editable)
{
  for (QWidget* w : caseGroup_->findChildren<QWidget*>()) w->setEnabled(editable);
}

void IntraoperativeUpdatePanel::updateControls()
{
  const bool ready = isPrepared();
  setCaseEditable(!ready && !preparing_);
  watch_->setEnabled(ready);
  loadScan_->setEnabled(ready);
  cancel_->setEnabled(running_);
  watchFolder_->setEnabled(!isWatching());
}

void IntraoperativeUpdatePanel::joinWorker()
{
  if (worker_.joinable()) worker_.join();
}

void IntraoperativeUpdatePanel::prepareCase()
{
  if (preparing_ || isPrepared()) return;
  const RunOptions options = caseOptions();
  QString problem;
  if (options.preopImage.empty() || options.preopLabels.empty()) problem = tr("Choose the preoperative MRI and its labels.");
  else if (options.outputDir.empty()) problem = tr("Choose the session folder.");
  std::shared_ptr<IntraoperativeUpdateLogic> logic;
  if (problem.isEmpty()) {
    try {
      logic = std::make_shared<IntraoperativeUpdateLogic>(options); // the configuration checked
    } catch (const std::exception& e) {
      problem = QString::fromStdString(e.what());
    }
  }
  if (!problem.isEmpty()) {
    status_->setText(problem);
    emit prepared(false);
    return;
  }
  joinWorker();
  preparing_ = true;
  status_->setText(tr("Preparing the case: reading and checking the preoperative data..."));
  updateControls();
  worker_ = std::thread([logic, panel = QPointer<IntraoperativeUpdatePanel>(this)] {
    std::string error;
    try {
      logic->prepare([panel](const UpdateProgress& step) { // the mesh, the preoperative boundary, the served worker
        const QString line = QString::fromStdString(step.message.empty() ? "preparing: " + step.stage : step.message);
        onGuiThread(panel, [line](IntraoperativeUpdatePanel& self) { self.status_->setText(line); });
      });
    } catch (const std::exception& e) {
      error = e.what();
    }
    onGuiThread(panel, [logic, error](IntraoperativeUpdatePanel& self) {
      self.preparing_ = false;
      if (error.empty()) self.logic_ = logic;
      QString message = error.empty() ? tr("Case prepared. Watch the scanner's folder or load a scan.")
                                      : tr("The case cannot be prepared: %1").arg(QString::fromStdString(error));
      if (error.find("earlier watch session") != std::string::npos) {
        message += tr(" (here: tick \"Replace an earlier session in this folder\", or choose another folder)");
      }
      self.status_->setText(message);
      self.updateControls();
      emit self.prepared(error.empty());
      self.startNextScan();
    });
  });
}

void IntraoperativeUpdatePanel::startWatching()
{
  if (!isPrepared()) return;
  if (watchFolder_->text().trimmed().isEmpty()) {
    status_->setText(tr("Choose the scanner's folder to watch."));
    watch_->setChecked(false);
    return;
  }
  try {
    watcher_ = std::make_unique<ScanFolderWatcher>(watchFolder_->text().trimmed().toStdString());
  } catch (const std::exception& e) {
    status_->setText(QString::fromStdString(e.what()));
    watch_->setChecked(false);
    return;
  }
  poll_->start();
  watch_->setChecked(true);
  status_->setText(tr("Watching %1 for scans.").arg(watchFolder_->text()));
  updateControls();
}

void IntraoperativeUpdatePanel::stopWatching()
{
  poll_->stop();
  watch_->setChecked(false);
  updateControls();
}

void IntraoperativeUpdatePanel::pollWatchedFolder()
{
  if (!watcher_) return;
  while (auto scan = watcher_->next()) enqueue(QString::fromStdString(scan->string()), tr("the watched folder"));
}

void IntraoperativeUpdatePanel::addScan(const QString& file)
{
  enqueue(file, tr("loaded in the host"));
}

void IntraoperativeUpdatePanel::enqueue(const QString& file, const QString& source)
{
  queue_.emplace_back(file, source);
  startNextScan();
}

void IntraoperativeUpdatePanel::startNextScan()
{
  if (running_ || preparing_ || queue_.empty() || !isPrepared()) return;
  const auto [file, from] = queue_.front();
  queue_.erase(queue_.begin());
  joinWorker();
  running_ = true;
  progress_->setRange(0, int(pipelineStages().size()));
  progress_->setValue(0);
  progress_->setFormat(tr("scan %1: starting").arg(history_.size() + 1));
  status_->setText(tr("Updating with %1...").arg(file));
  updateControls();
  const std::string source = from.toStdString();
  worker_ = std::thread([logic = logic_, file = file.toStdString(), source, panel = QPointer<IntraoperativeUpdatePanel>(this)] {
    const UpdateProgressCallback progress = [panel](const UpdateProgress& step) {
      onGuiThread(panel, [step](IntraoperativeUpdatePanel& self) { self.onProgress(step); });
    };
    const ScanUpdate scan = logic->update(file, source, progress);
    std::shared_ptr<ShownScan> shown;
    if (scan.registered || scan.trust == "rejected") shown = readScanResult(scan.outputDir); // the rigid result when rejected
    onGuiThread(panel, [scan, shown](IntraoperativeUpdatePanel& self) { self.onScanFinished(scan, shown); });
  });
}

void IntraoperativeUpdatePanel::onProgress(const UpdateProgress& step)
{
  progress_->setValue(int(step.index));
  progress_->setFormat(tr("scan %1: %2 (%3 of %4)")
                         .arg(history_.size() + 1)
                         .arg(QString::fromStdString(step.stage))
                         .arg(step.index + 1)
                         .arg(step.count));
  if (!step.message.empty()) status_->setText(QString::fromStdString(step.message));
  emit stageProgress(int(step.index), int(step.count), QString::fromStdString(step.stage), QString::fromStdString(step.message));
}

void IntraoperativeUpdatePanel::cancel()
{
  if (!running_ || !logic_) return;
  logic_->cancel();
  status_->setText(tr("Cancelling: the update stops at its next check; the views keep what they show."));
}

void IntraoperativeUpdatePanel::onScanFinished(const ScanUpdate& scan, std::shared_ptr<ShownScan> shown)
{
  running_ = false;
  history_.push_back(scan);
  addHistoryRow(scan);
  progress_->setValue(scan.registered ? progress_->maximum() : progress_->value());
  progress_->setFormat(tr("scan %1: %2").arg(scan.number).arg(QString::fromStdString(scan.outcome.substr(0, scan.outcome.find(':')))));
  if (shown && shown->error.empty()) {
    present(*shown, scan.number);
    status_->setText(tr("Scan %1 in %2 s.").arg(scan.number).arg(scan.wallSeconds, 0, 'f', 1));
  } else {
    status_->setText(shown ? QString::fromStdString(shown->error) : QString::fromStdString(scan.outcome));
  }
  showTrust(scan);
  updateControls();
  emit scanFinished(scan.number, QString::fromStdString(scan.outcome), QString::fromStdString(scan.trust));
  startNextScan();
  if (!running_) emit idle();
}

void IntraoperativeUpdatePanel::addHistoryRow(const ScanUpdate& scan)
{
  const int row = scans_->rowCount();
  scans_->insertRow(row);
  QStringList warnings;
  for (const std::string& w : scan.warnings) warnings << QString::fromStdString(w);
  const QString cells[] = {QString::number(scan.number), QString::number(scan.wallSeconds, 'f', 1),
                           QString::fromStdString(scan.outcome), QString::fromStdString(scan.trust), QString::number(warnings.size())};
  for (int column = 0; column < 5; ++column) {
    auto* item = new QTableWidgetItem(cells[column]);
    item->setToolTip(column == 4 ? warnings.join("\n") : QString::fromStdString(scan.intraopImage.string()));
    scans_->setItem(row, column, item);
  }
}

void IntraoperativeUpdatePanel::showTrust(const ScanUpdate& scan)
{
  QString reasons;
  for (const std::string& w : scan.warnings) {
    if (w.find("non-rigid update") != std::string::npos) reasons = QString::fromStdString(w);
  }
  const QString views = shownScan_ ? tr("the views show scan %1").arg(shownScan_) : tr("the views show no scan yet");
  QString text, colour;
  if (scan.cancelled) {
    trustState_ = "cancelled", colour = "#d0d0d0";
    text = tr("Scan %1 was cancelled; %2.").arg(scan.number).arg(views);
  } else if (scan.trust == "rejected") {
    trustState_ = "rejected", colour = "#f4a6a6";
    text = tr("Scan %1: the non-rigid update is REJECTED. The views show the rigid registration alone. %2").arg(scan.number).arg(reasons);
  } else if (!scan.registered) {
    trustState_ = "failed", colour = "#f4a6a6";
    text = tr("Scan %1 FAILED (%2); %3.").arg(scan.number).arg(QString::fromStdString(scan.outcome)).arg(views);
  } else if (scan.trust == "doubtful") {
    trustState_ = "doubtful", colour = "#f7d98b";
    text = tr("Scan %1: the non-rigid update is DOUBTFUL; check it against the scan before use. %2").arg(scan.number).arg(reasons);
  } else {
    trustState_ = QString::fromStdString(scan.trust), colour = "#b5e3b5";
    text = tr("Scan %1: the non-rigid update is %2.").arg(scan.number).arg(QString::fromStdString(scan.trust));
  }
  trust_->setText(text);
  trust_->setStyleSheet(QString("QLabel { background: %1; padding: 6px; font-weight: bold; }").arg(colour));
  trust_->setVisible(true);
}

void IntraoperativeUpdatePanel::present(ShownScan& shown, unsigned number)
{
  scene_.clear();
  scene_.moveNodesFrom(shown.scene);
  shownScan_ = number;
  focus_ = shown.focus;
  overlayIds_.clear();
  overlayChoice_->clear();
  // The warped statistics and angiograms first, in the scene's order; the confidence map last.
  std::vector<std::shared_ptr<ScalarVolumeNode>> overlays;
  for (const auto& volume : scene_.nodesOfType<ScalarVolumeNode>()) {
    if (volume->role() == "overlay") overlays.push_back(volume);
  }
  std::stable_partition(overlays.begin(), overlays.end(), [](const auto& v) { return v->name() != DisplacementUncertaintyNodeName; });
  for (const auto& volume : overlays) {
    overlayIds_.push_back(volume->id());
    overlayChoice_->addItem(QString::fromStdString(volume->name()));
  }
  choose(0);
  if (focus_ && context_.showPoint) context_.showPoint(*focus_);
  // Other panels follow the scene too, once its events are over (the fusion panel picks its layers
  // by role then): the surgeon's layers are set again after theirs.
  QTimer::singleShot(0, this, [this, number] {
    if (shownScan_ == number) choose(overlayChoice_->currentIndex());
  });
  for (int row = 0; row < scans_->rowCount(); ++row) {
    if (scans_->item(row, 0)->text().toUInt() == number) scans_->selectRow(row);
  }
}

void IntraoperativeUpdatePanel::choose(int overlayIndex)
{
  if (!context_.showLayers) return;
  ViewLayers layers;
  const SliceViewLayers& written = scene_.sliceViewLayers();
  layers.backgroundId = written.backgroundVolumeId;
  layers.labelMapId = written.labelVolumeId;
  layers.labelOutline = true; // the anatomy stays readable under the warped labels
  if (overlayIndex >= 0 && std::size_t(overlayIndex) < overlayIds_.size()) layers.overlayId = overlayIds_[std::size_t(overlayIndex)];
  if (overlayChoice_->currentIndex() != overlayIndex && overlayIndex < overlayChoice_->count()) overlayChoice_->setCurrentIndex(overlayIndex);
  context_.showLayers(layers);
}

void IntraoperativeUpdatePanel::showScan(int row)
{
  if (row < 0 || std::size_t(row) >= history_.size()) return;
  const ScanUpdate& scan = history_[std::size_t(row)];
  if (!(scan.registered || scan.trust == "rejected")) {
    status_->setText(tr("Scan %1 has no result to show (%2).").arg(scan.number).arg(QString::fromStdString(scan.outcome)));
    return;
  }
  const std::shared_ptr<ShownScan> shown = readScanResult(scan.outputDir);
  if (!shown->error.empty()) {
    status_->setText(QString::fromStdString(shown->error));
    return;
  }
  present(*shown, scan.number);
  showTrust(scan);
  status_->setText(tr("Showing scan %1.").arg(scan.number));
}

} // namespace brainshift
