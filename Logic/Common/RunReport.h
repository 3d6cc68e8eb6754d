#pragma once
// report.json (../shared/CONTRACT.md): one object per stage that ran, keyed by its subcommand
// name, each with "wall_seconds" and its figures, and a top-level "warnings" list. Each stage
// merges its entry into the file the earlier stages wrote.
#include <nlohmann/json.hpp>

#include <chrono>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

namespace brainshift {

class RunReport {
public:
  /// Loads `file` if it exists (InputError if it is not a report), or starts an empty report.
  explicit RunReport(std::filesystem::path file);

  /// Sets (replaces) a stage's entry; `figures` must be an object, "wall_seconds" among them.
  void setStage(const std::string& stage, const nlohmann::json& figures);
  bool hasStage(const std::string& stage) const;
  const nlohmann::json& stage(const std::string& stage) const;
  /// The stage's entry, or an empty object when the stage has not run.
  nlohmann::json stageOrEmpty(const std::string& stage) const { return hasStage(stage) ? this->stage(stage) : nlohmann::json::object(); }

  /// Sets a top-level entry other than the stages (e.g. "case", "brainshift_version").
  void set(const std::string& key, const nlohmann::json& value);

  /// Starts afresh: no stages, entries or warnings (the file is replaced on the next save).
  void clear()
  {
    document_ = nlohmann::json::object();
    replaceable_.clear();
  }

  void addWarning(const std::string& warning);
  void addWarnings(const std::vector<std::string>& warnings);
  /// Withdraws the warnings that begin with `prefix` (what a later step of the run overturned);
  /// returns how many.
  std::size_t withdrawWarnings(const std::string& prefix);
  /// Warnings about a result that a later run of the same step replaces (the active surface fitted
  /// again by the refine stage's passes): those `source` gave last time are withdrawn, these added,
  /// so the report speaks of the result that stands and not of both.
  void replaceWarnings(const std::string& source, const std::vector<std::string>& warnings);
  const nlohmann::json& document() const { return document_; }

  /// Writes the report atomically.
  void save() const;

private:
  std::filesystem::path file_;
  nlohmann::json document_;
  std::map<std::string, std::vector<std::string>> replaceable_; ///< each source's warnings, as last given
};

/// Wall time since construction, in seconds.
class Stopwatch {
public:
  Stopwatch() : start_(std::chrono::steady_clock::now()) {}
  double seconds() const
  {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

private:
  std::chrono::steady_clock::time_point start_;
};

} // namespace brainshift
