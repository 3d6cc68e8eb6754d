// brainshift bench update: the speed-against-accuracy study of the whole intraoperative update on
// the built-in case. Each setting of the knobs that trade one for the other runs `register` as a
// user would (every stage, files and all) and is scored by the landmarks' TRE against the truth;
// the rigid registration alone is one point of the chart. Charts: Testing/Benchmarks/update/.
#include "AtomicFile.h"
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "LandmarkEvaluation.h"
#include "RunCommands.h"
#include "TransformIO.h"

#include <nlohmann/json.hpp>

#include <cstdio>
#include <memory>
#include <sstream>
#include <utility>
#include <vector>

namespace brainshift::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct UpdateBenchOptions {
  fs::path outputDir;
  std::string size = "full";
  std::vector<double> meshResolutions{3, 4, 5, 6};
  std::vector<double> meshGradings{0, 1}; ///< uniform, and graded (finer at the interfaces, coarser inside)
  std::vector<double> solverTolerances{1e-8, 1e-5}; ///< the last: the stage's default (the variants run it)
  std::vector<unsigned> surfaceIterations{200, 10};
  std::vector<double> shifts{5, 15};
  std::vector<double> rigidSamplings{1.0, 0.5, 0.25}; ///< the rigid registration's share of samples
  std::vector<unsigned> rigidLevels{3, 2};              ///< and pyramid levels (4, 2, 1 mm; 2: no 1 mm level)
  bool variants = true;
  bool serialScans = true; ///< a later scan of the default case after an earlier one (register --previous)
};

struct Setting {
  std::string caseName;
  double meshResolutionMm;
  double solverTolerance;
  unsigned surfaceIterations;
  double rigidSampling = 1.0;
  unsigned rigidLevels = 3;
  double meshGrading = 0.0;
};

struct NamedCase {
  std::string name;
  CaseParameters parameters;
};

/// The cases: the default and its variants (shift size, craniotomy site, no resection).
std::vector<NamedCase> benchCases(const UpdateBenchOptions& o)
{
  CaseParameters defaults;
  defaults.size = o.size == "full" ? CaseSize::Full : CaseSize::Small;
  std::vector<NamedCase> cases{{"default", defaults}};
  if (!o.variants) return cases;
  for (double shift : o.shifts) {
    CaseParameters p = defaults;
    p.shiftMillimetres = shift;
    std::ostringstream name;
    name << "shift-" << shift;
    cases.push_back({name.str(), p});
  }
  CaseParameters parietal = defaults;
  parietal.craniotomy = CraniotomySite::LeftParietal;
  cases.push_back({"left-parietal", parietal});
  CaseParameters intact = defaults;
  intact.resection = false;
  cases.push_back({"no-resection", intact});
  return cases;
}

/// One `register` as a user runs it (every stage, files and all), timed.
struct Registration {
  fs::path outputDir;
  json report;
  double seconds = 0;
};

/// `previous`: an earlier scan's output folder of the same case (empty: a first scan).
Registration registerCase(const CaseFiles& files, const fs::path& outputDir, const Setting& s, const fs::path& previous,
                          SerialScanSession* session = nullptr)
{
  RunOptions run;
  run.preopImage = files.preopImage;
  run.preopLabels = files.preopLabels;
  run.intraopImage = files.intraopImage;
  run.overlays = {"fmri=" + files.preopFmri.string()};
  run.outputDir = outputDir;
  run.previous = previous;
  run.meshResolutionMm = s.meshResolutionMm;
  run.meshGrading = s.meshGrading;
  std::ostringstream solver;
  solver << "-ksp_rtol " << s.solverTolerance;
  run.solverOptions = solver.str();
  Configuration configuration = configurationFor(run);
  configuration.surfaceMaximumIterations = s.surfaceIterations;
  configuration.rigidSamplingFraction = s.rigidSampling;
  configuration.rigidLevels = s.rigidLevels;
  std::error_code ec;
  fs::create_directories(run.outputDir, ec);
  RunReport report(run.outputDir / "report.json");
  RunContext context(run, configuration, report);
  if (session) context.joinSession(*session);
  Stopwatch clock;
  runRegistration(context);
  return Registration{run.outputDir, report.document(), clock.seconds()};
}

/// update_bench.csv, rewritten after each row (a long run can be read early), and a line per row.
class UpdateBenchTable {
public:
  explicit UpdateBenchTable(fs::path file) : file_(std::move(file))
  {
    csv_ << "case,method,mesh_resolution_mm,solver_rtol,surface_iterations,equations,total_seconds,rigid_seconds,classify_seconds,"
            "mesh_seconds,surface_seconds,simulate_seconds,simulate_solve_seconds,warp_seconds,tre_mean_mm,tre_p95_mm,tre_max_mm,"
            "tre_craniotomy_mm,tre_near_cavity_mm,tre_brain_mm,folded_voxels,rigid_sampling,rigid_levels,mesh_grading\n";
  }

  void row(const std::string& caseName, const std::string& method, const Setting& s, const Registration& r,
           const RegistrationError& tre, bool rigidOnly);

private:
  fs::path file_;
  std::ostringstream csv_;
};

void UpdateBenchTable::row(const std::string& caseName, const std::string& method, const Setting& s, const Registration& r,
                           const RegistrationError& tre, bool rigidOnly)
{
  const json& stages = r.report["stages"];
  auto seconds = [&](const char* stage) { return stages[stage]["wall_seconds"].get<double>(); };
  auto group = [&](const char* name) { return tre.groups.count(name) ? tre.groups.at(name).meanMm : -1.0; };
  if (rigidOnly) {
    csv_ << caseName << ',' << method << ",,,,0," << seconds("rigid") << ',' << seconds("rigid") << ",,,,,,,";
  } else {
    csv_ << caseName << ',' << method << ',' << s.meshResolutionMm << ',' << s.solverTolerance << ',' << s.surfaceIterations << ','
         << stages["simulate"]["equations"].get<long long>() << ',' << r.seconds << ',' << seconds("rigid") << ','
         << seconds("classify") << ',' << seconds("mesh") << ',' << seconds("surface") << ',' << seconds("simulate") << ','
         << stages["simulate"]["solve_seconds"].get<double>() << ',' << seconds("warp") << ',';
  }
  csv_ << tre.overall.meanMm << ',' << tre.overall.p95Mm << ',' << tre.overall.maxMm << ',' << group("craniotomy") << ','
       << group("near-cavity") << ',' << group("brain") << ',';
  if (!rigidOnly) csv_ << stages["warp"]["folded_voxels"].get<long long>();
  csv_ << ',' << s.rigidSampling << ',' << s.rigidLevels << ',' << s.meshGrading << '\n';
  std::printf("  %s, %s, mesh %.1f mm grading %g, rtol %.0e, surface %u iterations, rigid sampling %.2f, %u levels: TRE %.2f mm mean, "
              "%.2f p95, %.1f s\n", caseName.c_str(), method.c_str(), s.meshResolutionMm, s.meshGrading, s.solverTolerance, s.surfaceIterations,
              s.rigidSampling, s.rigidLevels, tre.overall.meanMm, tre.overall.p95Mm,
              rigidOnly ? seconds("rigid") : r.seconds);
  std::fflush(stdout);
  writeTextFileAtomically(file_, csv_.str());
}

/// The default case: every combination of the knobs, then the rigid registration's sampling and
/// pyramid at the product's defaults otherwise; a variant: the product's defaults.
std::vector<Setting> settingsFor(const NamedCase& named, const UpdateBenchOptions& o, const Setting& defaultSetting)
{
  std::vector<Setting> settings;
  if (named.name != "default") {
    Setting variant = defaultSetting;
    variant.caseName = named.name;
    settings.push_back(variant);
    return settings;
  }
  for (double h : o.meshResolutions) {
    for (double grading : o.meshGradings) {
      for (double tolerance : o.solverTolerances) {
        for (unsigned iterations : o.surfaceIterations) {
          Setting setting{named.name, h, tolerance, iterations};
          setting.meshGrading = grading;
          settings.push_back(setting);
        }
      }
    }
  }
  for (double sampling : o.rigidSamplings) {
    for (unsigned levels : o.rigidLevels) {
      if (sampling == 1.0 && levels == 3) continue; // the default setting, run above
      Setting rigid = defaultSetting;
      rigid.rigidSampling = sampling;
      rigid.rigidLevels = levels;
      settings.push_back(rigid);
    }
  }
  return settings;
}

bool isProductDefault(const Setting& s, const Setting& defaultSetting)
{
  return s.meshResolutionMm == defaultSetting.meshResolutionMm && s.solverTolerance == defaultSetting.solverTolerance &&
         s.surfaceIterations == defaultSetting.surfaceIterations && s.meshGrading == defaultSetting.meshGrading &&
         s.rigidSampling == 1.0 && s.rigidLevels == 3;
}

/// Serial scans: an earlier scan of the same case (the brain sunk by 5 mm, the tumour still there)
/// registered first, then this scan as the later one, reusing what the first prepared; then the
/// same two scans in one `brainshift watch` session (the preoperative data read once, the finite
/// element worker served between them).
void runSerialScans(const NamedCase& named, const CaseFiles& files, const SimulatedCase& simulated, const Setting& s,
                    const fs::path& work, UpdateBenchTable& table)
{
  CaseParameters early = named.parameters;
  early.shiftMillimetres = 5;
  early.resection = false;
  const CaseFiles earlyFiles(work / "serial" / "case-early");
  writeCase(simulateCase(early), early, earlyFiles.folder);
  const Registration first = registerCase(earlyFiles, work / "serial" / "scan-1", s, {});
  const Registration later = registerCase(files, work / "serial" / "scan-2", s, first.outputDir);
  table.row(named.name, "brainshift-later-scan", s, later,
            evaluateTransform(*readTransform(later.outputDir / "intraop_to_preop.h5"), simulated.landmarks), false);
  SerialScanSession session;
  const Registration watchedFirst = registerCase(earlyFiles, work / "serial" / "watch-1", s, {}, &session);
  const Registration watchedLater = registerCase(files, work / "serial" / "watch-2", s, watchedFirst.outputDir, &session);
  table.row(named.name, "brainshift-watch-later-scan", s, watchedLater,
            evaluateTransform(*readTransform(watchedLater.outputDir / "intraop_to_preop.h5"), simulated.landmarks), false);
}

/// The runs' files are large; the table is what stays, with each case's inputs (for other tools'
/// comparisons on the same images, such as elastix in run.sh).
void removeRunFiles(const fs::path& work)
{
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(work, ec)) {
    for (const auto& run : fs::directory_iterator(entry.path(), ec)) {
      if (run.path().filename().string().rfind("case", 0) != 0) fs::remove_all(run.path(), ec);
    }
  }
}

/// Each setting of one case: a registration scored by the landmarks (the first also gives the
/// rigid registration's row), and for the default setting of the default case the serial scans.
void benchCase(const NamedCase& named, const UpdateBenchOptions& o, const Setting& defaultSetting, const fs::path& work,
               UpdateBenchTable& table)
{
  const SimulatedCase simulated = simulateCase(named.parameters);
  const CaseFiles files(work / named.name / "case");
  writeCase(simulated, named.parameters, files.folder);
  bool rigidRecorded = false;
  for (const Setting& s : settingsFor(named, o, defaultSetting)) {
    std::ostringstream tag;
    tag << "mesh" << s.meshResolutionMm << "-grading" << s.meshGrading << "-rtol" << s.solverTolerance << "-surf" << s.surfaceIterations;
    const Registration r = registerCase(files, work / named.name / tag.str(), s, {});
    if (!rigidRecorded) { // the rigid registration alone, as the reference point
      const RegistrationError rigid = evaluateTransform(*readTransform(r.outputDir / "rigid_intraop_to_preop.tfm"), simulated.landmarks);
      table.row(named.name, "rigid", s, r, rigid, true);
      rigidRecorded = true;
    }
    table.row(named.name, "brainshift", s, r, evaluateTransform(*readTransform(r.outputDir / "intraop_to_preop.h5"), simulated.landmarks),
              false);
    if (o.serialScans && named.name == "default" && isProductDefault(s, defaultSetting)) {
      runSerialScans(named, files, simulated, s, work, table);
    }
  }
}

void runUpdateBench(const UpdateBenchOptions& o)
{
  if (o.size != "full" && o.size != "small") throw InputError("--size: '" + o.size + "' is neither full nor small");
  std::error_code ec;
  fs::create_directories(o.outputDir, ec);
  const fs::path work = o.outputDir / "runs";
  fs::remove_all(work, ec);
  if (o.meshResolutions.empty() || o.solverTolerances.empty() || o.surfaceIterations.empty()) {
    throw InputError("--mesh-resolutions, --solver-tolerances and --surface-iterations need at least one value each");
  }
  const std::vector<NamedCase> cases = benchCases(o);
  UpdateBenchTable table(o.outputDir / "update_bench.csv");
  const Configuration productDefaults;
  Setting defaultSetting{"default", productDefaults.meshResolutionMm, o.solverTolerances.back(), productDefaults.surfaceMaximumIterations};
  defaultSetting.meshGrading = productDefaults.meshGrading;
  for (const NamedCase& named : cases) benchCase(named, o, defaultSetting, work, table);
  removeRunFiles(work);
}

} // namespace

void addUpdateBenchCommand(CLI::App& bench)
{
  auto o = std::make_shared<UpdateBenchOptions>();
  CLI::App* command = bench.add_subcommand(
    "update", "The whole update: landmark TRE against wall time over mesh resolution, solver tolerance and active-surface "
              "iterations, on the built-in case and its variants (shift, craniotomy site, no resection)");
  command->add_option("--output-dir", o->outputDir, "where the measurements go")->required();
  command->add_option("--size", o->size, "full or small case")->capture_default_str();
  command->add_option("--mesh-resolutions", o->meshResolutions, "mesh resolutions, mm")->delimiter(',')->capture_default_str();
  command->add_option("--mesh-gradings", o->meshGradings, "mesh gradings (0: uniform)")->delimiter(',')->capture_default_str();
  command->add_option("--solver-tolerances", o->solverTolerances, "relative solver tolerances")->delimiter(',')->capture_default_str();
  command->add_option("--surface-iterations", o->surfaceIterations, "active surface iteration limits")->delimiter(',')->capture_default_str();
  command->add_option("--shifts", o->shifts, "shift sizes of the variants, mm")->delimiter(',')->capture_default_str();
  command->add_option("--rigid-samplings", o->rigidSamplings, "the rigid registration's shares of samples")->delimiter(',')->capture_default_str();
  command->add_option("--rigid-levels", o->rigidLevels, "the rigid registration's pyramid levels (1 to 3)")->delimiter(',')->capture_default_str();
  command->add_flag("!--no-variants", o->variants, "only the default case");
  command->add_flag("!--no-serial-scans", o->serialScans, "no later scan of the default case after an earlier one");
  command->callback([o] {
    for (double h : o->meshResolutions) {
      if (!(h >= 1 && h <= 10)) throw InputError("--mesh-resolutions: each must be within 1 to 10 mm");
    }
    for (double g : o->meshGradings) {
      if (!(g >= 0 && g <= 10)) throw InputError("--mesh-gradings: each must be within 0 (uniform) to 10");
    }
    for (double t : o->solverTolerances) {
      if (!(t > 0 && t < 1)) throw InputError("--solver-tolerances: each must be within 0 and 1");
    }
    for (unsigned i : o->surfaceIterations) {
      if (i < 1) throw InputError("--surface-iterations: each must be at least 1");
    }
    for (double f : o->rigidSamplings) {
      if (!(f >= 0.05 && f <= 4)) throw InputError("--rigid-samplings: each must be within 0.05 to 4");
    }
    for (unsigned l : o->rigidLevels) {
      if (l < 1 || l > 3) throw InputError("--rigid-levels: each must be within 1 to 3");
    }
    runUpdateBench(*o);
  });
}

} // namespace brainshift::cli
