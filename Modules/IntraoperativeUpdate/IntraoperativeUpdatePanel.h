#pragma once
// The surgeon's panel: the whole intraoperative update, scan after scan. Before surgery the case is
// chosen (preoperative image, labels, overlays such as fMRI or MRA, the session's output folder)
// and prepared (IntraoperativeUpdateLogic: the preoperative data read and checked once). Then
// scans come from a watched folder (the scanner's export, NIfTI/NRRD/MetaImage, each taken once it
// is complete) or are loaded by hand; each runs the whole update off the GUI thread, the stage and
// its lines on a progress bar, Cancel stopping it at the next check (the scene is untouched until a
// scan's result is in). A result replaces the scene: the new scan with the warped overlay and the
// warped labels over it, the slices through the strongest activation (else the tumour), the
// displacement-coloured brain surface, the confidence map among the overlays. The trust in the
// non-rigid update is shown above all else: trusted, doubtful (its reasons), or rejected (the views
// show the rigid registration). Each scan of the session is listed with its time, outcome, trust
// and warnings; choosing one shows it again.
#include "IntraoperativeUpdateLogic.h"
#include "ModulePlugin.h"

#include <QPointer>
#include <QStringList>
#include <QWidget>

#include <array>
#include <memory>
#include <optional>
#include <thread>

class QCheckBox;
class QComboBox;
class QLabel;
class QLineEdit;
class QProgressBar;
class QPushButton;
class QTableWidget;
class QTimer;

namespace brainshift {

class IntraoperativeUpdatePanel : public QWidget {
  Q_OBJECT
  Q_PROPERTY(QString statusText READ statusText)
  Q_PROPERTY(QString trustState READ trustState)
public:
  struct ShownScan; ///< a scan's result read aside, ready for the views

  IntraoperativeUpdatePanel(Scene& scene, const ModuleContext& context, QWidget* parent = nullptr);
  ~IntraoperativeUpdatePanel() override; ///< cancels a running update and waits for it

  /// The case's fields (what the user types or browses): overlays as NAME=FILE. Invokable, as
  /// are the slots, for the host's command line (brainshift-host --preop-image ... --scan ...).
  Q_INVOKABLE void setCase(const QString& preopImage, const QString& preopLabels, const QStringList& overlays, const QString& outputFolder,
               const QString& configFile = QString());
  Q_INVOKABLE void setReplaceEarlierSession(bool replace);
  void setWatchFolder(const QString& folder);
  void setPollMilliseconds(int milliseconds);

  QPushButton* prepareButton() const { return prepare_; }
  /// The case's configuration file: the host's (`--config`, ModuleContext) until the user sets another.
  QLineEdit* configurationField() const { return config_; }
  QPushButton* watchButton() const { return watch_; }
  QPushButton* cancelButton() const { return cancel_; }
  QProgressBar* progressBar() const { return progress_; }
  QTableWidget* scanTable() const { return scans_; }
  QComboBox* overlayChoice() const { return overlayChoice_; }
  QString statusText() const;
  QString trustText() const;
  /// "trusted", "doubtful", "rejected", "failed", "cancelled" or "" (nothing shown yet).
  QString trustState() const { return trustState_; }
  bool isPrepared() const;
  bool isRunning() const { return running_; }
  bool isWatching() const;
  /// The scan the views show (its number), 0 for none.
  unsigned shownScan() const { return shownScan_; }
  /// Where the views' cursor was put for the shown scan (LPS mm), if anywhere.
  std::optional<std::array<double, 3>> focusPoint() const { return focus_; }
  const std::vector<ScanUpdate>& scans() const { return history_; }

public slots:
  /// Prepares the case off the GUI thread: prepared(ok) when done.
  void prepareCase();
  void startWatching();
  void stopWatching();
  /// Queues a scan; it runs when the scans before it are done.
  void addScan(const QString& file);
  /// Stops the running update at its next check; its scan is listed as cancelled.
  void cancel();
  /// Shows a listed scan's result (its row in the table) in the views.
  void showScan(int row);

signals:
  void prepared(bool ok);
  /// A stage started (`message` empty) or reported a line.
  void stageProgress(int index, int count, const QString& stage, const QString& message);
  /// A scan ended: its number, outcome ("registered", "cancelled", "failed: ...") and trust.
  void scanFinished(unsigned number, const QString& outcome, const QString& trust);
  /// A scan ended and none waits: the views show the session's latest result.
  void idle();

private:
  void enqueue(const QString& file, const QString& source);
  void buildCaseGroup();
  void buildScanGroup();
  RunOptions caseOptions() const;
  void setCaseEditable(bool editable);
  void updateControls();
  void pollWatchedFolder();
  void startNextScan();
  void joinWorker();
  void onProgress(const UpdateProgress& progress);
  void onScanFinished(const ScanUpdate& scan, std::shared_ptr<ShownScan> shown);
  void addHistoryRow(const ScanUpdate& scan);
  void showTrust(const ScanUpdate& scan);
  void present(ShownScan& shown, unsigned number);
  void choose(int overlayIndex);

  Scene& scene_;
  ModuleContext context_;
  QLineEdit *preopImage_, *preopLabels_, *overlays_, *outputFolder_, *config_, *watchFolder_;
  QCheckBox* replaceEarlier_;
  QPushButton *prepare_, *watch_, *loadScan_, *cancel_;
  QProgressBar* progress_;
  QLabel *status_, *trust_;
  QTableWidget* scans_;
  QComboBox* overlayChoice_;
  QTimer* poll_;
  QWidget *caseGroup_, *scanGroup_;

  std::shared_ptr<IntraoperativeUpdateLogic> logic_;
  std::unique_ptr<ScanFolderWatcher> watcher_;
  std::thread worker_;
  bool running_ = false;
  bool preparing_ = false;
  std::vector<std::pair<QString, QString>> queue_; ///< scans waiting, with where each came from
  std::vector<ScanUpdate> history_;
  unsigned shownScan_ = 0;
  std::optional<std::array<double, 3>> focus_;
  QString trustState_;
  std::vector<std::string> overlayIds_; ///< the overlay choice's nodes, in its order
};

} // namespace brainshift
