#include "StageRunControls.h"

#include <QHBoxLayout>
#include <QLabel>
#include <QProgressBar>
#include <QPushButton>
#include <QVBoxLayout>

#include <algorithm>

namespace brainshift {

StageRunControls::StageRunControls(const QString& stageName, QWidget* parent)
  : QWidget(parent)
  , stageName_(stageName)
{
  run_ = new QPushButton(tr("Run"), this);
  run_->setObjectName("runButton");
  cancel_ = new QPushButton(tr("Cancel"), this);
  cancel_->setObjectName("cancelButton");
  progress_ = new QProgressBar(this);
  progress_->setTextVisible(false);
  status_ = new QLabel(tr("Idle"), this);
  status_->setWordWrap(true);
  status_->setObjectName("status");
  work_ = new BackgroundRun(this);

  auto* buttons = new QHBoxLayout;
  buttons->addWidget(run_);
  buttons->addWidget(cancel_);
  auto* column = new QVBoxLayout(this);
  column->setContentsMargins(0, 0, 0, 0);
  column->addLayout(buttons);
  column->addWidget(progress_);
  column->addWidget(status_);

  connect(run_, &QPushButton::clicked, this, &StageRunControls::runRequested);
  connect(cancel_, &QPushButton::clicked, this, &StageRunControls::cancel);
  connect(work_, &BackgroundRun::failed, this, [this](const QString& message) {
    setRunning(false);
    setStatus(tr("%1 failed: %2").arg(stageName_, message));
    emit finished(false);
  });
  connect(work_, &BackgroundRun::discarded, this, &StageRunControls::discarded);
  setRunning(false);
}

QString StageRunControls::statusText() const
{
  return status_->text();
}

void StageRunControls::setStatus(const QString& text)
{
  status_->setText(text);
}

bool StageRunControls::start(const QString& message, std::function<BackgroundRun::Delivery(CancelFlag)> work)
{
  if (!work_->start(std::move(work))) return false;
  setRunning(true);
  setStatus(message);
  return true;
}

void StageRunControls::finish(bool succeeded, const QString& status)
{
  setRunning(false);
  if (succeeded) {
    progress_->setRange(0, 100);
    progress_->setValue(100);
  }
  setStatus(status);
  emit finished(succeeded);
}

void StageRunControls::showFraction(double fraction)
{
  if (!isRunning()) return; // a late report of a cancelled run
  progress_->setRange(0, 100);
  progress_->setValue(int(100.0 * std::clamp(fraction, 0.0, 1.0)));
}

void StageRunControls::cancel()
{
  if (!isRunning()) return;
  work_->cancel();
  setRunning(false);
  setStatus(tr("Cancelled."));
}

void StageRunControls::setRunning(bool running)
{
  run_->setEnabled(!running);
  cancel_->setEnabled(running);
  progress_->setRange(0, running ? 0 : 100); // a busy bar until the logic reports a fraction
  progress_->setValue(0);
  emit runningChanged(running);
}

} // namespace brainshift
