// The patch test: a linear displacement field imposed on the boundary is reproduced inside, on an
// irregular mesh, to 1e-10 (a direct solve, so that only the discretization is tested).
#include "BrainShiftTestingSupport.h"
#include "FiniteElementTestSupport.h"

#include <iostream>

int FiniteElementPatchTest(int, char*[])
{
  return brainshift::testing::runTest("FiniteElementPatchTest", [] {
    using namespace brainshift;
    const testing::Field linear = [](const double* x) {
      return std::array<double, 3>{0.02 * x[0] - 0.01 * x[1] + 0.005 * x[2] + 0.3, 0.015 * x[0] + 0.01 * x[2] - 0.2,
                                   -0.01 * x[0] + 0.02 * x[1] - 0.03 * x[2] + 0.1};
    };
    FiniteElementJob job = testing::cubeMesh(5, 40.0, 0.25);
    testing::imposeOnBoundary(job, 40.0, linear);
    job.solverOptions = "-ksp_type preonly -pc_type lu";
    std::vector<std::string> stages;
    FiniteElementRunOptions options = testing::workerOptions();
    options.progress = [&](const std::string& stage, double) { stages.push_back(stage); };
    const FiniteElementResult result = solveWithWorker(job, options);
    const double error = testing::maximumNodalError(job, result, linear);
    std::cout << "patch test: max nodal error " << error << " mm, " << result.equations << " equations, " << result.solver << '\n';
    BS_CHECK_MSG(error < 1e-10, error);
    BS_CHECK(result.equations == 3 * std::int64_t(job.nodeCount()));
    BS_CHECK(result.convergedReason > 0);
    BS_CHECK(result.solver == "lu+petsc");
    BS_CHECK(!stages.empty() && stages.back() == "done");
    // The same with the default one-shot solver (CG + block Jacobi/ICC) and with CG + GAMG (the
    // default above its size limit), to their tolerance.
    for (const char* options : {"-ksp_rtol 1e-12", "-pc_type gamg -ksp_rtol 1e-12"}) {
      job.solverOptions = options;
      const FiniteElementResult iterative = solveWithWorker(job, testing::workerOptions());
      BS_CHECK_MSG(iterative.solver == (job.solverOptions.find("gamg") != std::string::npos ? "cg+gamg" : "cg+bjacobi/icc"), iterative.solver);
      BS_CHECK_MSG(testing::maximumNodalError(job, iterative, linear) < 1e-8, testing::maximumNodalError(job, iterative, linear));
    }
  });
}
