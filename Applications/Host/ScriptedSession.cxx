#include "ScriptedSession.h"

#include <QVariant>

#include <cstdio>

namespace brainshift {

ScriptedSession::ScriptedSession(QObject* panel, QStringList scans, std::function<void(bool)> done)
  : QObject(panel)
  , panel_(panel)
  , scans_(std::move(scans))
  , done_(std::move(done))
{
  connect(panel, SIGNAL(prepared(bool)), this, SLOT(onPrepared(bool)));
  connect(panel, SIGNAL(scanFinished(uint, QString, QString)), this, SLOT(onScanFinished(uint, QString, QString)));
  connect(panel, SIGNAL(idle()), this, SLOT(onIdle()));
}

void ScriptedSession::onPrepared(bool ok)
{
  if (!ok) {
    std::fprintf(stderr, "brainshift-host: the case cannot be prepared: %s\n", qPrintable(panel_->property("statusText").toString()));
    done_(false);
    return;
  }
  if (scans_.isEmpty()) {
    done_(true);
    return;
  }
  for (const QString& scan : scans_) QMetaObject::invokeMethod(panel_, "addScan", Q_ARG(QString, scan));
}

void ScriptedSession::onScanFinished(unsigned number, const QString& outcome, const QString& trust)
{
  std::printf("brainshift-host: scan %u: %s; the non-rigid update is %s\n", number, qPrintable(outcome), qPrintable(trust));
  std::fflush(stdout);
  if (outcome != "registered") allRegistered_ = false;
}

void ScriptedSession::onIdle()
{
  done_(allRegistered_);
}

} // namespace brainshift
