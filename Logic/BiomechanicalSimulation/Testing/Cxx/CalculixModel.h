#pragma once
// A finite element job as a CalculiX (ccx) model, for an independent check of the worker: the
// input deck, the run, and the displacements read back from the .dat file.
//
// C3D4 node order: CalculiX's shape functions (shape4tet.f) are N1 = 1 - xi - eta - zeta,
// N2 = xi, N3 = eta, N4 = zeta, so its Jacobian is det[p2 - p1, p3 - p1, p4 - p1]: the job's
// positive orientation (p1 - p0) . ((p2 - p0) x (p3 - p0)) > 0 is accepted as is. A negatively
// oriented tetrahedron is rejected ("*ERROR in e_c3d: nonpositive jacobian", checked with ccx 2.20).
#include "BrainShiftTestingSupport.h"
#include "ExternalProgram.h"
#include "FiniteElementJob.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <string>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

namespace brainshift::testing {

using brainshift::findOnPath;
using brainshift::shellQuoted;

/// Writes `folder`/`name`.inp: nodes and C3D4 elements with 1-based ids, one element set, material
/// and solid section per material, the imposed displacements of the fixed nodes per dof, one
/// linear static step printing U of every node to `name`.dat. Numbers carry 13 significant digits.
inline void writeCalculixInput(const FiniteElementJob& job, const std::filesystem::path& folder, const std::string& name)
{
  std::ofstream inp(folder / (name + ".inp"));
  // ccx reads a number from at most 20 characters: 13 significant digits, "-1.234567890123e-18".
  inp << std::scientific << std::setprecision(12);
  inp << "** BrainShift FiniteElementJob: " << job.nodeCount() << " nodes, " << job.tetrahedronCount() << " C3D4\n";
  inp << "*NODE, NSET=Nall\n";
  for (std::size_t v = 0; v < job.nodeCount(); ++v) {
    inp << v + 1 << ", " << job.nodes[3 * v] << ", " << job.nodes[3 * v + 1] << ", " << job.nodes[3 * v + 2] << '\n';
  }
  for (std::size_t m = 0; m < job.materials.size(); ++m) {
    bool any = false;
    for (std::size_t t = 0; t < job.tetrahedronCount(); ++t) {
      if (std::size_t(job.materialOfTetrahedron[t]) != m) continue;
      if (!any) inp << "*ELEMENT, TYPE=C3D4, ELSET=Mat" << m << '\n';
      any = true;
      inp << t + 1;
      for (int k = 0; k < 4; ++k) inp << ", " << job.tetrahedra[4 * t + std::size_t(k)] + 1;
      inp << '\n';
    }
    if (!any) continue; // an unused material: no set to attach it to
    inp << "*MATERIAL, NAME=Mat" << m << "\n*ELASTIC\n"
        << job.materials[m].youngsModulus << ", " << job.materials[m].poissonRatio << '\n';
    inp << "*SOLID SECTION, ELSET=Mat" << m << ", MATERIAL=Mat" << m << '\n';
  }
  inp << "*STEP\n*STATIC\n*BOUNDARY\n";
  for (std::size_t f = 0; f < job.fixedNodes.size(); ++f) {
    for (int d = 0; d < 3; ++d) {
      inp << job.fixedNodes[f] + 1 << ", " << d + 1 << ", " << d + 1 << ", " << job.fixedDisplacements[3 * f + std::size_t(d)] << '\n';
    }
  }
  inp << "*NODE PRINT, NSET=Nall\nU\n*END STEP\n";
  if (!inp) throw std::runtime_error("cannot write " + (folder / (name + ".inp")).string());
}

/// Runs `ccx -i name` in `folder` (one thread: deterministic, and polite to a shared machine);
/// fails the test with ccx's output when it exits non-zero, reports an error, or does not finish.
inline void runCalculix(const std::filesystem::path& ccx, const std::filesystem::path& folder, const std::string& name)
{
  const std::filesystem::path log = folder / "ccx.log";
  const std::string command = "cd " + shellQuoted(folder.string()) +
                              " && OMP_NUM_THREADS=1 CCX_NPROC_STIFFNESS=1 CCX_NPROC_EQUATION_SOLVER=1 CCX_NPROC_RESULTS=1 " +
                              shellQuoted(ccx.string()) + " -i " + shellQuoted(name) + " > ccx.log 2>&1 < /dev/null";
  const int status = std::system(command.c_str());
  std::ifstream in(log);
  std::stringstream output;
  output << in.rdbuf();
  const std::string text = output.str();
  const bool exited = status != -1 && WIFEXITED(status);
  const int code = exited ? WEXITSTATUS(status) : -1;
  // ccx exits 0 even for a missing input deck: its own error markers and "Job finished" decide too.
  BS_CHECK_MSG(exited && code == 0 && text.find("*ERROR") == std::string::npos && text.find("Job finished") != std::string::npos,
               "ccx failed (status " << status << ", exit code " << code << ") in " << folder << ":\n" << text);
}

/// The displacements (3 per node, 0-based node order) of `folder`/`name`.dat as written by
/// *NODE PRINT with U: a header line "displacements (vx,vy,vz) for set ..." and one line
/// "id ux uy uz" per node. Every node must appear exactly once.
inline std::vector<double> readCalculixDisplacements(const std::filesystem::path& folder, const std::string& name, std::size_t nodeCount)
{
  const std::filesystem::path dat = folder / (name + ".dat");
  std::ifstream in(dat);
  BS_CHECK_MSG(in, "cannot read " << dat);
  std::vector<double> displacements(3 * nodeCount, 0.0);
  std::vector<char> seen(nodeCount, 0);
  std::size_t count = 0;
  bool inBlock = false, anyBlock = false;
  std::string line;
  while (std::getline(in, line)) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    if (line.find("displacements") != std::string::npos) {
      BS_CHECK_MSG(!anyBlock, "more than one displacement block in " << dat);
      inBlock = anyBlock = true;
      continue;
    }
    if (line.find_first_of("abcdfghijklmnopqrstuvwxyz(") != std::string::npos) { // another block ('e' is an exponent)
      inBlock = false;
      continue;
    }
    if (!inBlock) continue;
    std::istringstream fields(line);
    long long id = 0;
    double u[3];
    std::string rest;
    BS_CHECK_MSG((fields >> id >> u[0] >> u[1] >> u[2]) && !(fields >> rest), "unreadable line in " << dat << ": '" << line << "'");
    BS_CHECK_MSG(id >= 1 && std::size_t(id) <= nodeCount, "node id " << id << " out of range in " << dat);
    BS_CHECK_MSG(!seen[std::size_t(id - 1)], "node " << id << " twice in " << dat);
    seen[std::size_t(id - 1)] = 1;
    ++count;
    for (int d = 0; d < 3; ++d) displacements[3 * std::size_t(id - 1) + std::size_t(d)] = u[d];
  }
  BS_CHECK_MSG(count == nodeCount, dat << " has " << count << " of " << nodeCount << " nodes");
  return displacements;
}

} // namespace brainshift::testing
