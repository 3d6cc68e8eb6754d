#include "RunReport.h"

#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "ProcessMemory.h"

#include <algorithm>

namespace brainshift {
namespace fs = std::filesystem;

RunReport::RunReport(fs::path file)
  : file_(std::move(file))
{
  std::error_code ec;
  if (fs::exists(file_, ec)) {
    try {
      document_ = nlohmann::json::parse(readTextFile(file_));
    } catch (const nlohmann::json::exception& e) {
      throw InputError(file_.string() + ": not a valid report (" + e.what() + ")");
    }
    if (!document_.is_object() || (document_.contains("stages") && !document_["stages"].is_object())) {
      throw InputError(file_.string() + ": not a BrainShift report (no \"stages\" object)");
    }
  }
  if (!document_.is_object()) document_ = nlohmann::json::object();
  if (!document_.contains("stages")) document_["stages"] = nlohmann::json::object();
  if (!document_.contains("warnings")) document_["warnings"] = nlohmann::json::array();
}

void RunReport::setStage(const std::string& stage, const nlohmann::json& figures)
{
  if (!figures.is_object() || !figures.contains("wall_seconds")) {
    throw std::invalid_argument("report entry of stage '" + stage + "' needs an object with wall_seconds");
  }
  document_["stages"][stage] = figures;
}

bool RunReport::hasStage(const std::string& stage) const
{
  return document_.contains("stages") && document_["stages"].contains(stage);
}

const nlohmann::json& RunReport::stage(const std::string& stage) const
{
  if (!document_.contains("stages")) throw std::out_of_range("the report has no stage '" + stage + "'");
  return document_["stages"].at(stage);
}

void RunReport::set(const std::string& key, const nlohmann::json& value)
{
  if (key == "stages" || key == "warnings") throw std::invalid_argument("use setStage/addWarning for " + key);
  document_[key] = value;
}

void RunReport::addWarning(const std::string& warning)
{
  auto& warnings = document_["warnings"];
  if (std::find(warnings.begin(), warnings.end(), warning) == warnings.end()) warnings.push_back(warning);
}

void RunReport::addWarnings(const std::vector<std::string>& warnings)
{
  for (const auto& w : warnings) addWarning(w);
}

void RunReport::replaceWarnings(const std::string& source, const std::vector<std::string>& warnings)
{
  std::vector<std::string>& earlier = replaceable_[source];
  if (!earlier.empty() && document_.contains("warnings")) {
    nlohmann::json kept = nlohmann::json::array();
    for (const auto& w : document_["warnings"]) {
      if (!(w.is_string() && std::find(earlier.begin(), earlier.end(), w.get<std::string>()) != earlier.end())) kept.push_back(w);
    }
    document_["warnings"] = std::move(kept);
  }
  // Only what this source adds is its own: a warning another step gave already stays when this one
  // replaces its own.
  earlier.clear();
  auto& all = document_["warnings"];
  for (const auto& w : warnings) {
    if (std::find(all.begin(), all.end(), w) != all.end()) continue;
    all.push_back(w);
    earlier.push_back(w);
  }
}

std::size_t RunReport::withdrawWarnings(const std::string& prefix)
{
  if (!document_.contains("warnings")) return 0;
  nlohmann::json& warnings = document_["warnings"];
  const std::size_t before = warnings.size();
  nlohmann::json kept = nlohmann::json::array();
  for (const auto& w : warnings) {
    if (!(w.is_string() && w.get<std::string>().rfind(prefix, 0) == 0)) kept.push_back(w);
  }
  warnings = std::move(kept);
  return before - warnings.size();
}

void RunReport::save() const
{
  nlohmann::json written = document_;
  written["huge_page_allocations"] = hugePageAllocations(); // the last writer's process, as its times are
  writeTextFileAtomically(file_, written.dump(2) + "\n");
}

} // namespace brainshift
