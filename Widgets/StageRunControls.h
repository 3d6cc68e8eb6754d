#pragma once
// What every stage panel has below its inputs: Run and Cancel, a progress bar and a status line,
// and the background run behind them (BackgroundRun.h). The panel gives the work (run off the GUI
// thread, with the run's cancel flag for the logic) and, on the GUI thread, what its result does to
// the scene; these controls keep the buttons, the bar and the status in step with the run, and say
// when the panel's inputs must be locked (runningChanged).
#include "BackgroundRun.h"

#include <QWidget>

class QLabel;
class QProgressBar;
class QPushButton;

namespace brainshift {

class StageRunControls : public QWidget {
  Q_OBJECT
public:
  /// `stageName` opens the failure message: "<stageName> failed: <reason>".
  explicit StageRunControls(const QString& stageName, QWidget* parent = nullptr);

  QPushButton* runButton() const { return run_; }
  QPushButton* cancelButton() const { return cancel_; }
  QProgressBar* progressBar() const { return progress_; }
  QString statusText() const;
  void setStatus(const QString& text);
  bool isRunning() const { return work_->isRunning(); }

  /// Starts `work` with `message` as the status and a busy bar; false (nothing started) while a run
  /// is going. The work's delivery must end the run with finish().
  bool start(const QString& message, std::function<BackgroundRun::Delivery(CancelFlag)> work);
  /// Ends the run (from its delivery): idle, `status` shown, finished(succeeded) emitted.
  void finish(bool succeeded, const QString& status);
  /// For logic that reports how far it is: the bar shows the fraction (0 to 1) from now on.
  void showFraction(double fraction);

public slots:
  /// Cancels the run: idle at once, the logic stops at its next check, its result is dropped.
  void cancel();

signals:
  void runRequested();               ///< Run was clicked
  void runningChanged(bool running); ///< the panel locks its inputs while running
  void finished(bool succeeded);     ///< a run ended with a result or a failure (not a cancel)
  void discarded(bool stoppedEarly); ///< a cancelled run's work ended (stoppedEarly: on the flag)

private:
  void setRunning(bool running);

  QString stageName_;
  QPushButton *run_, *cancel_;
  QProgressBar* progress_;
  QLabel* status_;
  BackgroundRun* work_;
};

} // namespace brainshift
