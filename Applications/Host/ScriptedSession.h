#pragma once
// The host's command line driving the "Intraoperative update" panel (a module plugin, known to
// the host only by its Qt interface): once the panel's case is prepared, each scan in turn; then
// `done(ok)` (ok: prepared, and every scan registered). For scripted sessions and screenshots
// (brainshift-host --preop-image ... --scan ...).
#include <QObject>
#include <QStringList>

#include <functional>

namespace brainshift {

class ScriptedSession : public QObject {
  Q_OBJECT
public:
  /// Follows `panel`'s prepared(bool), scanFinished(uint, QString, QString) and idle() signals;
  /// a child of the panel.
  ScriptedSession(QObject* panel, QStringList scans, std::function<void(bool)> done);

private slots:
  void onPrepared(bool ok);
  void onScanFinished(unsigned number, const QString& outcome, const QString& trust);
  void onIdle();

private:
  QObject* panel_;
  QStringList scans_;
  std::function<void(bool)> done_;
  bool allRegistered_ = true;
};

} // namespace brainshift
