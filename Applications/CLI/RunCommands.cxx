#include "RunCommands.h"

namespace brainshift::cli {
namespace fs = std::filesystem;

void addRunOptions(CLI::App* command, RunOptions& options, unsigned requiredInputs, unsigned offeredInputs,
                   bool solverFlags, bool meshFlags, bool classificationFlags)
{
  auto input = [&](InputFlag flag, const char* name, fs::path& target, const char* help) {
    if (!(offeredInputs & unsigned(flag))) return;
    CLI::Option* option = command->add_option(name, target, help);
    if (requiredInputs & unsigned(flag)) option->required();
  };
  input(InputFlag::PreopImage, "--preop-image", options.preopImage, "preoperative MRI (NIfTI, NRRD, MetaImage or a DICOM folder)");
  input(InputFlag::PreopLabels, "--preop-labels", options.preopLabels,
        "preoperative label map on the preoperative image's grid (0 background, 1 head, 2 parenchyma, 3 ventricles, 4 tumour)");
  input(InputFlag::IntraopImage, "--intraop-image", options.intraopImage, "intraoperative MRI");
  if (offeredInputs & unsigned(InputFlag::Overlays)) {
    command->add_option("--overlay", options.overlays,
                        "NAME=FILE: another preoperative volume (fMRI statistics, MRA) to warp; repeatable");
  }
  command->add_option("--output-dir", options.outputDir, "the case's output folder")->required();
  command->add_option("--config", options.config, "JSON configuration (materials, mesh, solver); flags override it");
  if (classificationFlags) {
    command->add_option("--prototypes", options.prototypes,
                        "classification prototypes: a previous scan's classification_prototypes.json, or a .mrk.json of "
                        "points named by tissue (parenchyma-1, ventricles-2, ...); default: chosen automatically");
    command->add_option("--tumour-resected", options.tumourResected,
                        "yes, no or auto: whether the tumour has been resected (auto: decided from the image where the "
                        "aligned tumour lies; the default)");
  }
  if (meshFlags) {
    command->add_option("--mesh-resolution", options.meshResolutionMm, "target tetrahedron edge length in mm (default 4)");
    command->add_option("--mesh-backend", options.meshBackend,
                        "lattice (Kuhn lattice, boundary nodes snapped; default) or cgal (CGAL Mesh_3)");
    command->add_option("--mesh-grading", options.meshGrading,
                        "lattice: element size grows by this many mm per mm away from the tissue interfaces, the brain's "
                        "surface and the region of interest (0: uniform)");
    command->add_option("--mesh-roi", options.meshRegionOfInterest,
                        "X,Y,Z,R: a sphere (LPS centre and radius, mm) meshed at --mesh-resolution throughout")
        ->delimiter(',')
        ->expected(4);
  }
  if (solverFlags) {
    command->add_option("--ranks", options.ranks, "MPI ranks of the finite element worker (default 2)");
    command->add_option("--solver-options", options.solverOptions,
                        "PETSc options over the tuned default, e.g. \"-ksp_type gmres -pc_type bjacobi\"");
  }
}

} // namespace brainshift::cli
