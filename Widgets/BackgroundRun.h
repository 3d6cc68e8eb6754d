#pragma once
// Long work off the GUI thread for the module panels. The work runs on Qt's thread pool and
// returns what to do with its result; that runs later on the GUI thread, so only the GUI thread
// ever touches the scene (Scene.h). Each run gets a cancel flag that the work hands to the logic
// (its parameters' `cancel`); cancel() sets it, the logic stops at its next check with
// CancelledError, and whatever the run still returns is dropped (discarded()). The panel is free at
// once. Destroying the runner cancels its run too, so no worker outlives its panel's interest.
#include "BrainShiftErrors.h"

#include <QObject>

#include <atomic>
#include <functional>
#include <memory>

namespace brainshift {

class BackgroundRun : public QObject {
  Q_OBJECT
public:
  /// Called on the GUI thread with the work's result (captured).
  using Delivery = std::function<void()>;

  explicit BackgroundRun(QObject* parent = nullptr);
  ~BackgroundRun() override;

  /// Starts `work` with this run's cancel flag; false (and nothing started) while a run is going.
  bool start(std::function<Delivery(CancelFlag)> work);
  /// Cancels the run: its flag is set, it is not running from now on, its delivery never happens.
  void cancel();
  bool isRunning() const { return running_; }

signals:
  /// The work threw; `message` is the exception's.
  void failed(const QString& message);
  /// The delivery ran.
  void delivered();
  /// The worker of a cancelled run ended; its result was dropped. `stoppedEarly`: the logic
  /// stopped on the cancel flag (CancelledError) rather than running to its end.
  void discarded(bool stoppedEarly);

private:
  struct Outcome;
  bool running_ = false;
  unsigned currentRun_ = 0; ///< a result of any other run than this one is dropped
  std::shared_ptr<std::atomic<bool>> cancelFlag_; ///< the current run's
};

} // namespace brainshift
