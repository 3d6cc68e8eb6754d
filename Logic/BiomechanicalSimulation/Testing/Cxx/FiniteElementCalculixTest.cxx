// An independent solver: the same heterogeneous problem on an irregular mesh solved by the worker
// and by CalculiX (ccx, linear static, C3D4), the nodal displacements agreeing to 1e-6 of the
// largest displacement. The imposed boundary field (a sag with a lateral shear) is not reproduced
// exactly by linear elements, so the two must agree on a genuine discrete solution, not on an
// interpolated exact one. Skipped (CTest return code 77) when ccx is not on PATH.
#include "BrainShiftTestingSupport.h"
#include "CalculixModel.h"
#include "FiniteElementTestSupport.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>

int FiniteElementCalculixTest(int, char*[])
{
  const std::filesystem::path ccx = brainshift::testing::findOnPath("ccx");
  if (ccx.empty()) {
    std::cout << "ccx not found: skipped\n";
    return 77; // SKIP_RETURN_CODE in CMakeLists.txt
  }
  return brainshift::testing::runTest("FiniteElementCalculixTest", [&ccx] {
    using namespace brainshift;
    using Clock = std::chrono::steady_clock;
    const double side = 40.0;
    const double pi = 3.14159265358979323846;
    FiniteElementJob job = testing::cubeMesh(6, side, 0.2);
    job.materials = {{3e-3, 0.45}, {1e-2, 0.3}}; // brain-like below z = 20 mm, stiffer above
    std::size_t upper = 0;
    for (std::size_t t = 0; t < job.tetrahedronCount(); ++t) {
      double cz = 0;
      for (int k = 0; k < 4; ++k) cz += job.nodes[3 * std::size_t(job.tetrahedra[4 * t + std::size_t(k)]) + 2] / 4.0;
      job.materialOfTetrahedron[t] = cz < 20.0 ? 0 : 1;
      upper += cz < 20.0 ? 0 : 1;
    }
    BS_CHECK(upper > 0 && upper < job.tetrahedronCount());
    const testing::Field imposed = [=](const double* p) {
      const double sx = std::sin(pi * p[0] / side), sy = std::sin(pi * p[1] / side), zeta = p[2] / side;
      return std::array<double, 3>{0.4 * zeta * zeta * sy, -0.25 * zeta * sx, -3.0 * sx * sy * zeta};
    };
    testing::imposeOnBoundary(job, side, imposed);
    job.solverOptions = "-ksp_type preonly -pc_type lu";

    auto start = Clock::now();
    const FiniteElementResult result = solveWithWorker(job, testing::workerOptions());
    const double workerSeconds = std::chrono::duration<double>(Clock::now() - start).count();
    BS_CHECK(result.displacements.size() == 3 * job.nodeCount());

    const std::filesystem::path folder = testing::temporaryFolder("FiniteElementCalculixTest");
    start = Clock::now();
    testing::writeCalculixInput(job, folder, "model");
    testing::runCalculix(ccx, folder, "model");
    const std::vector<double> reference = testing::readCalculixDisplacements(folder, "model", job.nodeCount());
    const double ccxSeconds = std::chrono::duration<double>(Clock::now() - start).count();

    // ccx prints 7 significant digits: up to half a unit of the last one of the difference is
    // its rounding; what is left beyond that is the two solvers' own disagreement.
    double largest = 0, difference = 0, interiorError = 0, beyondRounding = 0;
    std::size_t worst = 0;
    for (std::size_t v = 0; v < job.nodeCount(); ++v) {
      double magnitude = 0;
      for (int d = 0; d < 3; ++d) {
        const std::size_t i = 3 * v + std::size_t(d);
        magnitude += result.displacements[i] * result.displacements[i];
        if (std::abs(result.displacements[i] - reference[i]) > difference) {
          difference = std::abs(result.displacements[i] - reference[i]);
          worst = v;
        }
        const double printed = std::abs(reference[i]);
        const double halfUnit = printed > 0 ? 0.5e-6 * std::pow(10.0, std::floor(std::log10(printed))) : 0.0;
        beyondRounding = std::max(beyondRounding, std::abs(result.displacements[i] - reference[i]) - halfUnit);
      }
      largest = std::max(largest, std::sqrt(magnitude));
    }
    // The field itself is not the discrete solution inside (otherwise the check would be weak).
    interiorError = testing::maximumNodalError(job, result, imposed);
    const double relative = difference / largest;
    std::cout << job.nodeCount() << " nodes, " << job.tetrahedronCount() << " tetrahedra (" << upper
              << " stiff), " << job.fixedNodes.size() << " fixed\n"
              << "worker (" << result.solver << "): " << workerSeconds << " s; ccx: " << ccxSeconds << " s\n"
              << "max displacement " << largest << " mm, max difference " << difference << " mm at node " << worst
              << " (relative " << relative << "; beyond ccx's 7-digit print rounding: " << std::max(beyondRounding, 0.0)
              << " mm), imposed field off the solution by " << interiorError << " mm\n";
    BS_CHECK_MSG(interiorError > 1e-3, "the imposed field is reproduced exactly: " << interiorError);
    BS_CHECK_MSG(largest > 1.0, largest);
    BS_CHECK_MSG(relative < 1e-6, "worker and ccx differ by " << difference << " mm of " << largest << " mm at node " << worst);
  });
}
