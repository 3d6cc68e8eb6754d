// What goes wrong is said, and the caller survives: bad jobs, a missing worker, a solver that does
// not converge, a worker that hangs (timeout) or is cancelled.
#include "BrainShiftErrors.h"
#include "BrainShiftTestingSupport.h"
#include "FiniteElementTestSupport.h"

#include <chrono>
#include <cstring>
#include <thread>

int FiniteElementFailureTest(int, char*[])
{
  return brainshift::testing::runTest("FiniteElementFailureTest", [] {
    using namespace brainshift;
    const testing::Field shift = [](const double* x) { return std::array<double, 3>{0.0, 0.0, -0.01 * x[2]}; };
    FiniteElementJob good = testing::cubeMesh(4, 40.0);
    testing::imposeOnBoundary(good, 40.0, shift);

    FiniteElementJob job = good;
    std::swap(job.tetrahedra[1], job.tetrahedra[2]);
    BS_CHECK_THROWS(solveWithWorker(job, testing::workerOptions()), std::invalid_argument, "tetrahedron 0 is inverted");
    job = good;
    job.fixedNodes.clear();
    job.fixedDisplacements.clear();
    BS_CHECK_THROWS(solveWithWorker(job, testing::workerOptions()), std::invalid_argument, "singular");
    job = good;
    job.fixedNodes[0] = 100000;
    BS_CHECK_THROWS(solveWithWorker(job, testing::workerOptions()), std::invalid_argument, "boundary node 100000 does not exist");
    job = good;
    job.materials[0].poissonRatio = 0.5;
    BS_CHECK_THROWS(solveWithWorker(job, testing::workerOptions()), std::invalid_argument, "Poisson ratio 0.5 is outside"); // as given, not 0.500000
    job = good;
    job.materials[0].youngsModulus = std::nan("");
    BS_CHECK_THROWS(solveWithWorker(job, testing::workerOptions()), std::invalid_argument, "Young's modulus");

    FiniteElementRunOptions missing = testing::workerOptions();
    missing.worker = "/nonexistent/brainshift-fe-worker";
    BS_CHECK_THROWS(solveWithWorker(good, missing), MethodError, "missing");

    job = good;
    job.solverOptions = "-ksp_type cg -pc_type none -ksp_max_it 2 -ksp_rtol 1e-12";
    BS_CHECK_THROWS(solveWithWorker(job, testing::workerOptions()), MethodError, "did not converge");

    // A larger job: 24^3 cubes (a solve without a preconditioner that would run for days).
    FiniteElementJob big = testing::cubeMesh(24, 40.0);
    testing::imposeOnBoundary(big, 40.0, shift);
    big.solverOptions = "-ksp_type cg -pc_type none -ksp_rtol 1e-300 -ksp_atol 0 -ksp_max_it 100000000";
    // A factorisation that fails (MUMPS on two ranks, allowed 1 MB of working memory): the message
    // says why, with MUMPS's own error code, so that a failure seen once can be told apart.
    FiniteElementJob starved = big;
    starved.solverOptions = "-ksp_type preonly -pc_type cholesky -pc_factor_mat_solver_type mumps -mat_mumps_icntl_23 1";
    try {
      solveWithWorker(starved, testing::workerOptions(2));
      BS_CHECK_MSG(false, "a factorisation given 1 MB solved");
    } catch (const MethodError& e) {
      std::cout << e.what() << '\n';
      BS_CHECK_MSG(std::strstr(e.what(), "the preconditioner failed") && std::strstr(e.what(), "MUMPS INFOG(1) -"), e.what());
    }

    // A worker that hangs: a timeout stops the whole process group, quickly.
    FiniteElementRunOptions impatient = testing::workerOptions(2);
    impatient.timeoutSeconds = 1.5;
    const auto start = std::chrono::steady_clock::now();
    BS_CHECK_THROWS(solveWithWorker(big, impatient), MethodError, "timed out");
    const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    BS_CHECK_MSG(waited < 30.0, waited); // unstopped, this solve would run for days

    // Cancelled from another thread.
    std::atomic<bool> cancel{false};
    FiniteElementRunOptions cancellable = testing::workerOptions();
    cancellable.cancel = &cancel;
    std::thread canceller([&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(800));
      cancel = true;
    });
    BS_CHECK_THROWS(solveWithWorker(big, cancellable), MethodError, "cancelled");
    canceller.join();

    // And the good job still solves afterwards.
    FiniteElementJob tight = good;
    tight.solverOptions = "-ksp_rtol 1e-10";
    const FiniteElementResult result = solveWithWorker(tight, testing::workerOptions());
    BS_CHECK_MSG(testing::maximumNodalError(tight, result, shift) < 1e-6, testing::maximumNodalError(tight, result, shift));
  });
}
