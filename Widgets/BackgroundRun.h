#pragma once
// Long work off the GUI thread for the module panels. The work runs on Qt's thread pool and
// returns what to do with its result; that runs later on the GUI thread, so only the GUI thread
// ever touches the scene (Scene.h). Cancel abandons the run: the logic has no cancel hooks, so its
// worker goes on to its end and its result is then dropped (discarded()); the panel is free at once.
#include <QObject>

#include <functional>

namespace brainshift {

class BackgroundRun : public QObject {
  Q_OBJECT
public:
  /// Called on the GUI thread with the work's result (captured).
  using Delivery = std::function<void()>;

  explicit BackgroundRun(QObject* parent = nullptr);
  ~BackgroundRun() override;

  /// Starts `work`; false (and nothing started) while a run is going.
  bool start(std::function<Delivery()> work);
  /// Abandons the run: not running from now on; its delivery will never happen.
  void cancel();
  bool isRunning() const { return running_; }

signals:
  /// The work threw; `message` is the exception's.
  void failed(const QString& message);
  /// The delivery ran.
  void delivered();
  /// The worker of an abandoned run ended; its result was dropped.
  void discarded();

private:
  struct Outcome;
  bool running_ = false;
  unsigned currentRun_ = 0; ///< a result of any other run than this one is dropped
};

} // namespace brainshift
