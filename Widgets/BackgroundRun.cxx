#include "BackgroundRun.h"

#include <QFutureWatcher>
#include <QtConcurrent/QtConcurrentRun>

#include <exception>

namespace brainshift {

struct BackgroundRun::Outcome {
  unsigned run = 0;
  Delivery delivery;
  QString error;
};

BackgroundRun::BackgroundRun(QObject* parent)
  : QObject(parent)
{
}

// A worker still going when its owner is destroyed ends unobserved: its watcher goes with this
// object, and the work holds no reference to it.
BackgroundRun::~BackgroundRun() = default;

bool BackgroundRun::start(std::function<Delivery()> work)
{
  if (running_) return false;
  const unsigned run = ++currentRun_;
  auto* watcher = new QFutureWatcher<Outcome>(this);
  connect(watcher, &QFutureWatcher<Outcome>::finished, this, [this, watcher] {
    const Outcome outcome = watcher->result();
    watcher->deleteLater();
    if (outcome.run != currentRun_ || !running_) {
      emit discarded();
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
  watcher->setFuture(QtConcurrent::run([run, work = std::move(work)] {
    Outcome outcome;
    outcome.run = run;
    try {
      outcome.delivery = work();
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
  ++currentRun_;
  running_ = false;
}

} // namespace brainshift
