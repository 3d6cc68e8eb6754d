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

namespace brainshift::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct UpdateBenchOptions {
  fs::path outputDir;
  std::string size = "full";
  std::vector<double> meshResolutions{3, 4, 5, 6};
  std::vector<double> solverTolerances{1e-10, 1e-5};
  std::vector<unsigned> surfaceIterations{200, 10};
  std::vector<double> shifts{5, 15};
  bool variants = true;
};

struct Setting {
  std::string caseName;
  double meshResolutionMm;
  double solverTolerance;
  unsigned surfaceIterations;
};

void runUpdateBench(const UpdateBenchOptions& o)
{
  if (o.size != "full" && o.size != "small") throw InputError("--size: '" + o.size + "' is neither full nor small");
  std::error_code ec;
  fs::create_directories(o.outputDir, ec);
  const fs::path work = o.outputDir / "runs";
  fs::remove_all(work, ec);

  // The cases: the default and its variants (shift size, craniotomy site, no resection).
  struct NamedCase {
    std::string name;
    CaseParameters parameters;
  };
  CaseParameters defaults;
  defaults.size = o.size == "full" ? CaseSize::Full : CaseSize::Small;
  std::vector<NamedCase> cases{{"default", defaults}};
  if (o.variants) {
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
  }

  std::ostringstream csv;
  csv << "case,method,mesh_resolution_mm,solver_rtol,surface_iterations,equations,total_seconds,rigid_seconds,classify_seconds,"
         "mesh_seconds,surface_seconds,simulate_seconds,simulate_solve_seconds,warp_seconds,tre_mean_mm,tre_p95_mm,tre_max_mm,"
         "tre_craniotomy_mm,tre_near_cavity_mm,tre_brain_mm,folded_voxels\n";
  for (const NamedCase& named : cases) {
    const SimulatedCase simulated = simulateCase(named.parameters);
    const CaseFiles files(work / named.name / "case");
    writeCase(simulated, named.parameters, files.folder);
    std::vector<Setting> settings;
    if (named.name == "default") {
      for (double h : o.meshResolutions) {
        for (double tolerance : o.solverTolerances) {
          for (unsigned iterations : o.surfaceIterations) settings.push_back({named.name, h, tolerance, iterations});
        }
      }
    } else {
      settings.push_back({named.name, o.meshResolutions.front(), o.solverTolerances.front(), o.surfaceIterations.front()});
    }
    bool rigidRecorded = false;
    for (const Setting& s : settings) {
      std::ostringstream tag;
      tag << "mesh" << s.meshResolutionMm << "-rtol" << s.solverTolerance << "-surf" << s.surfaceIterations;
      RunOptions run;
      run.preopImage = files.preopImage;
      run.preopLabels = files.preopLabels;
      run.intraopImage = files.intraopImage;
      run.overlays = {"fmri=" + files.preopFmri.string()};
      run.outputDir = work / named.name / tag.str();
      run.meshResolutionMm = s.meshResolutionMm;
      std::ostringstream solver;
      solver << "-ksp_rtol " << s.solverTolerance;
      run.solverOptions = solver.str();
      Configuration configuration = configurationFor(run);
      configuration.surfaceMaximumIterations = s.surfaceIterations;
      fs::create_directories(run.outputDir, ec);
      RunReport report(run.outputDir / "report.json");
      RunContext context(run, configuration, report);
      Stopwatch clock;
      context.loadAllInputs();
      runPipeline(context);
      const double total = clock.seconds();
      const RegistrationError tre = evaluateTransform(*readTransform(run.outputDir / "intraop_to_preop.h5"), simulated.landmarks);
      auto seconds = [&](const char* stage) { return report.stage(stage)["wall_seconds"].get<double>(); };
      auto group = [&](const char* name) { return tre.groups.count(name) ? tre.groups.at(name).meanMm : -1.0; };
      if (!rigidRecorded) { // the rigid registration alone, as the reference point
        const RegistrationError rigid = evaluateTransform(*readTransform(run.outputDir / "rigid_intraop_to_preop.tfm"), simulated.landmarks);
        auto rigidGroup = [&](const char* name) { return rigid.groups.count(name) ? rigid.groups.at(name).meanMm : -1.0; };
        csv << named.name << ",rigid,,,,0," << seconds("rigid") << ',' << seconds("rigid") << ",,,,,,," << rigid.overall.meanMm << ','
            << rigid.overall.p95Mm << ',' << rigid.overall.maxMm << ',' << rigidGroup("craniotomy") << ','
            << rigidGroup("near-cavity") << ',' << rigidGroup("brain") << ",\n";
        rigidRecorded = true;
      }
      csv << named.name << ",brainshift," << s.meshResolutionMm << ',' << s.solverTolerance << ',' << s.surfaceIterations << ','
          << report.stage("simulate")["equations"].get<long long>() << ',' << total << ',' << seconds("rigid") << ','
          << seconds("classify") << ',' << seconds("mesh") << ',' << seconds("surface") << ',' << seconds("simulate") << ','
          << report.stage("simulate")["solve_seconds"].get<double>() << ',' << seconds("warp") << ',' << tre.overall.meanMm << ','
          << tre.overall.p95Mm << ',' << tre.overall.maxMm << ',' << group("craniotomy") << ',' << group("near-cavity") << ','
          << group("brain") << ',' << report.stage("warp")["folded_voxels"].get<long long>() << '\n';
      std::printf("  %s, mesh %.1f mm, rtol %.0e, surface %u iterations: TRE %.2f mm mean, %.2f p95, %.1f s\n", named.name.c_str(),
                  s.meshResolutionMm, s.solverTolerance, s.surfaceIterations, tre.overall.meanMm, tre.overall.p95Mm, total);
      std::fflush(stdout);
      writeTextFileAtomically(o.outputDir / "update_bench.csv", csv.str()); // as it goes: a long run can be read early
    }
  }
  fs::remove_all(work, ec); // the runs' files are large; the table is what stays
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
  command->add_option("--solver-tolerances", o->solverTolerances, "relative solver tolerances")->delimiter(',')->capture_default_str();
  command->add_option("--surface-iterations", o->surfaceIterations, "active surface iteration limits")->delimiter(',')->capture_default_str();
  command->add_option("--shifts", o->shifts, "shift sizes of the variants, mm")->delimiter(',')->capture_default_str();
  command->add_flag("!--no-variants", o->variants, "only the default case");
  command->callback([o] {
    for (double h : o->meshResolutions) {
      if (!(h >= 1 && h <= 10)) throw InputError("--mesh-resolutions: each must be within 1 to 10 mm");
    }
    for (double t : o->solverTolerances) {
      if (!(t > 0 && t < 1)) throw InputError("--solver-tolerances: each must be within 0 and 1");
    }
    for (unsigned i : o->surfaceIterations) {
      if (i < 1) throw InputError("--surface-iterations: each must be at least 1");
    }
    runUpdateBench(*o);
  });
}

} // namespace brainshift::cli
