// brainshift bench surface: the active surface's accuracy against the built-in case's truth, where
// it fails (shift size, corrupted brain masks), and its speed.
#include "ActiveSurfaceLogic.h"
#include "AtomicFile.h"
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "DistanceMaps.h"
#include "LabelMapMesher.h"
#include "RigidRegistrationLogic.h"
#include "RunReport.h"
#include "SurfaceDisplacementEvaluation.h"
#include "TissueClassificationLogic.h"

#include <CLI/CLI.hpp>
#include <itkSmoothingRecursiveGaussianImageFilter.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <random>
#include <sstream>

namespace brainshift::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

struct SurfaceBenchOptions {
  fs::path outputDir;
  std::string size = "full";
  std::vector<double> shifts{2, 5, 10, 15, 20};
  std::vector<double> corruption{0, 1, 2, 3, 4, 6};
  std::vector<std::string> methods{"segmentation", "guarded", "image-refined"};
  double meshResolutionMm = 3.0;
  unsigned runs = 3;
  std::uint64_t seed = 2000;
};

/// The case's true intraoperative labels with the brain's boundary moved in and out by a smooth
/// random field of standard deviation `amplitudeMm` (correlation about 5 mm): a classification that
/// is wrong in patches, as a deliberately corrupted brain mask.
LabelImage::Pointer corruptedBrain(const LabelImage& truth, double amplitudeMm, std::uint64_t seed)
{
  const std::size_t n = truth.GetLargestPossibleRegion().GetNumberOfPixels();
  auto copy = LabelImage::New();
  copy->SetRegions(truth.GetLargestPossibleRegion());
  copy->CopyInformation(&truth);
  copy->Allocate();
  std::copy(truth.GetBufferPointer(), truth.GetBufferPointer() + n, copy->GetBufferPointer());
  if (amplitudeMm <= 0) return copy;
  auto mask = MaskImage::New();
  mask->SetRegions(truth.GetLargestPossibleRegion());
  mask->CopyInformation(&truth);
  mask->Allocate();
  const LabelPixel* l = truth.GetBufferPointer();
  for (std::size_t i = 0; i < n; ++i) mask->GetBufferPointer()[i] = l[i] >= 2 ? 1 : 0;
  const ScalarImage::Pointer distance = boundaryDistanceMm(mask);
  auto noise = ScalarImage::New();
  noise->SetRegions(truth.GetLargestPossibleRegion());
  noise->CopyInformation(&truth);
  noise->Allocate();
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> gauss(0.0f, 1.0f);
  for (std::size_t i = 0; i < n; ++i) noise->GetBufferPointer()[i] = gauss(rng);
  auto smooth = itk::SmoothingRecursiveGaussianImageFilter<ScalarImage, ScalarImage>::New();
  smooth->SetInput(noise);
  smooth->SetSigma(5.0);
  smooth->Update();
  const float* g = smooth->GetOutput()->GetBufferPointer();
  double sum = 0, sum2 = 0;
  for (std::size_t i = 0; i < n; ++i) {
    sum += g[i];
    sum2 += double(g[i]) * g[i];
  }
  const double sd = std::sqrt(std::max(sum2 / double(n) - (sum / double(n)) * (sum / double(n)), 1e-12));
  const float* d = distance->GetBufferPointer();
  LabelPixel* out = copy->GetBufferPointer();
  for (std::size_t i = 0; i < n; ++i) {
    const bool brain = d[i] + amplitudeMm * g[i] / sd < 0;
    if (brain && out[i] < 2) out[i] = 2;   // grown: the outside taken for parenchyma
    if (!brain && out[i] >= 2) out[i] = 0; // eroded: brain taken for outside
  }
  return copy;
}

struct SurfaceScore {
  ActiveSurfaceResult result;
  SurfaceDisplacementAccuracy accuracy;
  double seconds = 0;
};

/// The variants compared: the segmentation alone; guarded by the image where the expected grey
/// levels contradict it (the default); and refined by the image's edge everywhere as well.
ActiveSurfaceParameters parametersOf(const std::string& method)
{
  ActiveSurfaceParameters parameters;
  parameters.imageRescue = method != "segmentation";
  parameters.imageWeight = method == "image-refined" ? 0.5 : 0.0;
  return parameters;
}

SurfaceScore scoreSurface(const SimulatedCase& c, const LabelMapMesh& mesh, const LabelImage& target, const SpatialTransform& rigid,
                          const std::string& method)
{
  const ActiveSurfaceParameters parameters = parametersOf(method);
  Stopwatch clock;
  SurfaceScore score;
  score.result = deformBrainSurface(mesh.mesh, c.preopLabels, target, c.intraopImage, rigid, parameters);
  score.seconds = clock.seconds();
  score.accuracy = evaluateSurfaceDisplacement(score.result.surface, *c.intraopToPreop, rigid, *c.preopLabels);
  return score;
}

/// surface_sweep.csv, and a line per row.
class SurfaceSweepTable {
public:
  SurfaceSweepTable()
  {
    csv_ << "variable,value,target,method,surface_nodes,imposed_nodes,iterations,mean_error_mm,p95_error_mm,max_error_mm,"
            "moving_nodes,moving_mean_error_mm,moving_true_mm,true_max_mm,true_mean_mm,residual_true_mm,residual_target_mm,seconds\n";
  }

  void row(const char* variable, double value, const char* target, const std::string& method, const SurfaceScore& s)
  {
    const SurfaceDisplacementAccuracy& a = s.accuracy;
    csv_ << variable << ',' << value << ',' << target << ',' << method << ',' << s.result.surfaceNodes << ','
         << s.result.imposedNodes << ',' << s.result.iterations << ',' << a.meanErrorMm << ',' << a.p95ErrorMm << ','
         << a.maxErrorMm << ',' << a.movingNodes << ',' << a.movingMeanErrorMm << ',' << a.movingMeanTrueDisplacementMm << ','
         << a.maxTrueDisplacementMm << ',' << a.meanTrueDisplacementMm << ',' << a.meanResidualMm << ','
         << s.result.meanResidualMm << ',' << s.seconds << '\n';
    std::printf("  %s %.1f, %s target, %s: error mean %.2f p95 %.2f mm (moving %.2f of %.2f mm), residual %.2f mm, %.2f s\n",
                variable, value, target, method.c_str(), a.meanErrorMm, a.p95ErrorMm, a.movingMeanErrorMm, a.movingMeanTrueDisplacementMm,
                a.meanResidualMm, s.seconds);
    std::fflush(stdout);
  }

  std::string text() const { return csv_.str(); }

private:
  std::ostringstream csv_;
};

/// Shift size: the true labels (the method alone) and the classification (the pipeline).
void sweepShifts(const SurfaceBenchOptions& o, const CaseParameters& defaults, const LabelMapMesh& mesh, SurfaceSweepTable& table)
{
  for (double shift : o.shifts) {
    CaseParameters parameters = defaults;
    parameters.shiftMillimetres = shift;
    const SimulatedCase c = simulateCase(parameters);
    const RigidRegistrationResult rigid = registerRigidly(*c.intraopImage, *c.preopImage, c.preopLabels, {});
    if (!rigid.trustworthy) throw MethodError("bench surface: the rigid registration failed at shift " + std::to_string(shift));
    TissueClassificationParameters classification;
    takePreoperativeImage(classification, *c.preopImage, *c.preopLabels, *rigid.intraopToPreop);
    const TissueClassificationResult classified =
      classifyTissues(*c.intraopImage, *c.preopLabels, *rigid.intraopToPreop, std::nullopt, classification);
    for (const std::string& method : o.methods) {
      table.row("shift", shift, "truth", method, scoreSurface(c, mesh, *c.intraopLabels, *rigid.intraopToPreop, method));
      table.row("shift", shift, "classified", method, scoreSurface(c, mesh, *classified.labels, *rigid.intraopToPreop, method));
    }
  }
}

/// Corrupted brain masks, on the default shift, with the true rigid transform (the mask alone varies).
void sweepCorruption(const SurfaceBenchOptions& o, const SimulatedCase& reference, const LabelMapMesh& mesh, SurfaceSweepTable& table)
{
  for (double amplitude : o.corruption) {
    const LabelImage::Pointer corrupted = corruptedBrain(*reference.intraopLabels, amplitude, o.seed + 17);
    for (const std::string& method : o.methods) {
      table.row("corruption", amplitude, "corrupted", method,
                scoreSurface(reference, mesh, *corrupted, *reference.rigidIntraopToPreop, method));
    }
  }
}

/// Speed on the default case: the stage's parts, median of the runs (surface_speed.json).
void benchSurfaceSpeed(const SurfaceBenchOptions& o, const SimulatedCase& reference, const LabelMapMesh& mesh)
{
  std::vector<double> total, preop, target, iterations;
  SurfaceScore last;
  for (unsigned run = 0; run < std::max(1u, o.runs); ++run) {
    last = scoreSurface(reference, mesh, *reference.intraopLabels, *reference.rigidIntraopToPreop, "guarded");
    total.push_back(last.seconds);
    preop.push_back(last.result.preopBoundarySeconds);
    target.push_back(last.result.targetSeconds);
    iterations.push_back(last.result.iterationSeconds);
  }
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  const json speed = {{"size", o.size},
                      {"mesh_resolution_mm", o.meshResolutionMm},
                      {"mesh_nodes", mesh.quality.nodes},
                      {"surface_nodes", last.result.surfaceNodes},
                      {"iterations", last.result.iterations},
                      {"runs", total.size()},
                      {"seconds_median", median(total)},
                      {"preop_boundary_seconds_median", median(preop)},
                      {"target_seconds_median", median(target)},
                      {"iteration_seconds_median", median(iterations)},
                      {"mean_error_mm", last.accuracy.meanErrorMm},
                      {"p95_error_mm", last.accuracy.p95ErrorMm},
                      {"residual_true_mm", last.accuracy.meanResidualMm}};
  writeTextFileAtomically(o.outputDir / "surface_speed.json", speed.dump(2) + "\n");
  std::printf("  speed: %.2f s (preoperative boundary %.2f s, target %.2f s, iterations %.2f s)\n", median(total), median(preop),
              median(target), median(iterations));
}

void runSurfaceBench(const SurfaceBenchOptions& o)
{
  if (o.size != "full" && o.size != "small") throw InputError("--size: '" + o.size + "' is neither full nor small");
  CaseParameters defaults;
  defaults.size = o.size == "full" ? CaseSize::Full : CaseSize::Small;
  defaults.seed = o.seed;
  std::printf("bench surface: %s case, mesh %.1f mm\n", o.size.c_str(), o.meshResolutionMm);
  std::fflush(stdout);
  const SimulatedCase reference = simulateCase(defaults);
  MeshingParameters meshing;
  meshing.resolutionMm = o.meshResolutionMm;
  const LabelMapMesh mesh = meshLabelMap(*reference.preopLabels, meshing);
  SurfaceSweepTable table;
  sweepShifts(o, defaults, mesh, table);
  sweepCorruption(o, reference, mesh, table);
  writeTextFileAtomically(o.outputDir / "surface_sweep.csv", table.text());
  benchSurfaceSpeed(o, reference, mesh);
}

} // namespace

void addSurfaceBenchCommand(CLI::App& bench)
{
  auto o = std::make_shared<SurfaceBenchOptions>();
  CLI::App* command = bench.add_subcommand(
    "surface", "Active surface: error against the truth by shift size and by corrupted brain masks, and its speed");
  command->add_option("--output-dir", o->outputDir, "where the measurements go")->required();
  command->add_option("--size", o->size, "full or small case")->capture_default_str();
  command->add_option("--shifts", o->shifts, "peak brain shifts, mm")->delimiter(',')->capture_default_str();
  command->add_option("--corruption", o->corruption, "brain mask corruption amplitudes, mm")->delimiter(',')->capture_default_str();
  command->add_option("--methods", o->methods, "segmentation, guarded (the default), image-refined")->delimiter(',')->capture_default_str();
  command->add_option("--mesh-resolution", o->meshResolutionMm, "mesh resolution, mm")->capture_default_str();
  command->add_option("--runs", o->runs, "timed runs on the default case")->capture_default_str();
  command->add_option("--seed", o->seed, "seed of the cases")->capture_default_str();
  command->callback([o] {
    for (double s : o->shifts) {
      if (!(s >= 0 && s <= 30)) throw InputError("--shifts: each must be within 0 to 30 mm");
    }
    for (double a : o->corruption) {
      if (!(a >= 0 && a <= 20)) throw InputError("--corruption: each must be within 0 to 20 mm");
    }
    for (const std::string& m : o->methods) {
      if (m != "segmentation" && m != "guarded" && m != "image-refined") throw InputError("--methods: unknown method '" + m + "'");
    }
    std::error_code ec;
    fs::create_directories(o->outputDir, ec);
    runSurfaceBench(*o);
  });
}

} // namespace brainshift::cli
