#include "BackgroundRun.h"

#include <QFutureWatcher>
#include <QtConcurrent/QtConcurrentRun>

#include <exception>

namespace brainshift {

struct BackgroundRun::Outcome {
  unsigned run = 0;
  Delivery delivery;
  QString error;
  bool cancelled = false; ///< ended by CancelledError
};

BackgroundRun::BackgroundRun(QObject* parent)
  : QObject(parent)
{
}

// A worker still going when its owner is destroyed is told to stop and ends unobserved: its
// watcher goes with this object, and the work holds no reference to it (only to its flag).
BackgroundRun::~BackgroundRun()
{
  if (cancelFlag_) cancelFlag_->store(true);
}

bool BackgroundRun::start(std::function<Delivery(CancelFlag)> work)
{
  if (running_) return false;
  const unsigned run = ++currentRun_;
  cancelFlag_ = std::make_shared<std::atomic<bool>>(false);
  std::shared_ptr<std::atomic<bool>> flag = cancelFlag_;
  auto* watcher = new QFutureWatcher<Outcome>(this);
  connect(watcher, &QFutureWatcher<Outcome>::finished, this, [this, watcher] {
    const Outcome outcome = watcher->result();
    watcher->deleteLater();
    if (outcome.run != currentRun_ || !running_) {
      emit discarded(outcome.cancelled);
      return;
    }
    running_ = false;
    if (!outcome.error.isEmpty()) {
      emit failed(outcome.error);
      return;
    }
    outcome.delivery();
    emit delivered();
  });
  running_ = true;
  watcher->setFuture(QtConcurrent::run([run, flag, work = std::move(work)] {
    Outcome outcome;
    outcome.run = run;
    try {
      outcome.delivery = work(flag.get());
    } catch (const CancelledError& e) {
      outcome.error = QString::fromStdString(e.what()); // dropped: a cancelled run is never current
      outcome.cancelled = true;
    } catch (const std::exception& e) {
      outcome.error = QString::fromStdString(e.what());
    } catch (...) {
      outcome.error = "an unknown error";
    }
    if (outcome.error.isEmpty() && !outcome.delivery) outcome.error = "the work returned nothing to deliver";
    return outcome;
  }));
  return true;
}

void BackgroundRun::cancel()
{
  if (!running_) return;
  if (cancelFlag_) cancelFlag_->store(true);
  ++currentRun_;
  running_ = false;
}

} // namespace brainshift
