#include "AtomicFile.h"
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "LandmarkEvaluation.h"
#include "OutputFolder.h"

#include <itkIdentityTransform.h>

#include <cstdio>
#include <iostream>
#include <memory>

namespace brainshift::cli {
namespace fs = std::filesystem;

namespace {
void printStatistics(const char* label, const ErrorStatistics& s)
{
  std::printf("%-14s %4zu  mean %7.3f  median %7.3f  p95 %7.3f  max %7.3f\n", label, s.count, s.meanMm, s.medianMm,
              s.p95Mm, s.maxMm);
}
} // namespace

void addEvaluateCommand(CLI::App& app)
{
  struct Options {
    fs::path transform, landmarks, json;
  };
  auto options = std::make_shared<Options>();
  CLI::App* command = app.add_subcommand(
    "evaluate", "Target registration error of an intraop_to_preop transform against landmark pairs (mm)");
  command->add_option("--transform", options->transform,
                      "ITK transform file (.tfm, .h5, .txt, .mat), displacement field image (x = y + d(y)), or "
                      "'identity' (no registration: the misalignment and the shift themselves)")
    ->required();
  command->add_option("--landmarks", options->landmarks,
                      "CSV: name,preop_x,preop_y,preop_z,intraop_x,intraop_y,intraop_z (LPS mm)")
    ->required();
  command->add_option("--json", options->json, "also write the result as JSON to this file");
  command->callback([options] {
    if (!options->json.empty()) refuseOutputOverInputs(options->json, {options->landmarks, options->transform}, "--json");
    const std::vector<LandmarkPair> pairs = readLandmarksCsv(options->landmarks);
    SpatialTransform::Pointer transform;
    if (options->transform == "identity") {
      transform = itk::IdentityTransform<double, 3>::New().GetPointer();
    } else {
      transform = readTransform(options->transform);
    }
    const RegistrationError error = evaluateTransform(*transform, pairs);
    std::printf("transform %s (%s)\nlandmarks %s\n", options->transform.c_str(), describeTransform(transform).c_str(),
                options->landmarks.c_str());
    std::printf("TRE (mm)      pairs\n");
    printStatistics("all", error.overall);
    for (const auto& [group, statistics] : error.groups) printStatistics(group.c_str(), statistics);
    std::printf("per pair (mm)\n");
    for (const auto& [name, mm] : error.pairs) std::printf("  %-24s %8.3f\n", name.c_str(), mm);
    if (!options->json.empty()) writeTextFileAtomically(options->json, toJsonText(error));
  });
}

} // namespace brainshift::cli
