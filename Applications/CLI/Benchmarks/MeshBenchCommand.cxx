// brainshift bench mesh: the meshing backends on the built-in full brain (its preoperative labels)
// over a range of resolutions: wall time, size, quality and each tissue's volume against its
// voxels. "graded" is the lattice with graded resolution (fine at the interfaces, coarser inside). Charts: Testing/Benchmarks/mesh/.
#include "AtomicFile.h"
#include "BrainShiftCaseSimulator.h"
#include "BrainShiftErrors.h"
#include "Commands.h"
#include "LabelMapMesher.h"
#include "RunReport.h"

#include <cstdio>
#include <memory>
#include <sstream>

namespace brainshift::cli {

namespace {
struct MeshBenchOptions {
  std::filesystem::path outputDir;
  std::string size = "full";
  std::vector<double> resolutions{1.5, 2, 3, 4, 5, 6};
  std::vector<std::string> backends{"lattice", "graded", "cgal"};
  double grading = 1.0; ///< of the "graded" lattice
};

void runMeshBench(const MeshBenchOptions& o)
{
  if (o.size != "full" && o.size != "small") throw InputError("--size: '" + o.size + "' is neither full nor small");
  CaseParameters parameters;
  parameters.size = o.size == "full" ? CaseSize::Full : CaseSize::Small;
  std::printf("bench mesh: %s case\n", o.size.c_str());
  const SimulatedCase simulated = simulateCase(parameters);
  std::ostringstream csv;
  csv << "backend,resolution_mm,seconds,nodes,tetrahedra,min_dihedral_degrees,max_dihedral_degrees,inverted,"
         "volume_error_2,volume_error_3,volume_error_4\n";
  for (const std::string& backend : o.backends) {
    for (double h : o.resolutions) {
      MeshingParameters mp;
      mp.resolutionMm = h;
      mp.backend = backend == "cgal" ? MeshingBackend::Cgal : MeshingBackend::Lattice;
      if (backend == "graded") mp.gradingRate = o.grading;
      Stopwatch clock;
      LabelMapMesh mesh;
      try {
        mesh = meshLabelMap(*simulated.preopLabels, mp);
      } catch (const InputError& e) { // a tissue vanishing at a coarse resolution is a result too
        csv << backend << ',' << h << ',' << clock.seconds() << ",,,,,,,,\n";
        std::printf("  %s %.1f mm: %s\n", backend.c_str(), h, e.what());
        continue;
      }
      const double seconds = clock.seconds();
      const MeshQuality& q = mesh.quality;
      csv << backend << ',' << h << ',' << seconds << ',' << q.nodes << ',' << q.tetrahedra << ',' << q.minimumDihedralDegrees << ','
          << q.maximumDihedralDegrees << ',' << q.invertedOrFlat;
      for (int tissue : {2, 3, 4}) {
        const double error = q.meshVolumeMl.count(tissue) ? q.meshVolumeMl.at(tissue) / q.voxelVolumeMl.at(tissue) - 1 : -1;
        csv << ',' << error;
      }
      csv << '\n';
      std::printf("  %s %.1f mm: %zu nodes, %zu tetrahedra, dihedral %.1f to %.1f, %.2f s\n", backend.c_str(), h, q.nodes,
                  q.tetrahedra, q.minimumDihedralDegrees, q.maximumDihedralDegrees, seconds);
      std::fflush(stdout);
      writeTextFileAtomically(o.outputDir / "mesh_benchmark.csv", csv.str()); // each row kept as it comes
    }
  }
}
} // namespace

void addMeshBenchCommand(CLI::App& bench)
{
  auto options = std::make_shared<MeshBenchOptions>();
  CLI::App* command = bench.add_subcommand("mesh", "Meshing backends: time, size, quality and volume error against resolution");
  command->add_option("--output-dir", options->outputDir, "where the measurements go")->required();
  command->add_option("--size", options->size, "full or small case")->capture_default_str();
  command->add_option("--resolutions", options->resolutions, "mesh resolutions, mm")->delimiter(',')->capture_default_str();
  command->add_option("--backends", options->backends, "lattice (uniform), graded (the lattice graded), cgal")
      ->delimiter(',')
      ->capture_default_str();
  command->add_option("--grading", options->grading, "the graded lattice's grading (mm of size per mm of distance)")
      ->capture_default_str();
  command->callback([options] {
    for (const std::string& b : options->backends) {
      if (b != "lattice" && b != "graded" && b != "cgal") throw InputError("--backends: '" + b + "' is not lattice, graded or cgal");
    }
    runMeshBench(*options);
  });
}

} // namespace brainshift::cli
