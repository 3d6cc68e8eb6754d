#include "FiniteElementJob.h"
#include "NumberText.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>
#include <stdexcept>
#include <unistd.h>

namespace brainshift {
namespace fs = std::filesystem;

namespace {
// Version 2: soft constraints and their rejection after the options; their outcome in the result.
constexpr char JobMagic[8] = {'B', 'S', 'F', 'E', 'J', 'O', 'B', '2'};
constexpr char ResultMagic[8] = {'B', 'S', 'F', 'E', 'R', 'E', 'S', '2'};
constexpr std::size_t SoftConstraintValues = 4 + 3 + 6; // weights, target, stiffness

class Writer {
public:
  explicit Writer(const fs::path& target)
    : target_(target)
    , temporary_(target.parent_path() / (".tmp-" + std::to_string(::getpid()) + "-" + target.filename().string()))
    , out_(temporary_, std::ios::binary)
  {
    if (!out_) throw std::runtime_error("cannot write " + temporary_.string());
  }
  template <class T>
  void value(const T& v) { out_.write(reinterpret_cast<const char*>(&v), sizeof(T)); }
  template <class T>
  void vector(const std::vector<T>& v)
  {
    value<std::uint64_t>(v.size());
    out_.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * sizeof(T)));
  }
  void string(const std::string& s)
  {
    value<std::uint64_t>(s.size());
    out_.write(s.data(), std::streamsize(s.size()));
  }
  void raw(const char* data, std::size_t n) { out_.write(data, std::streamsize(n)); }
  void commit()
  {
    out_.close();
    if (!out_) throw std::runtime_error("cannot write " + temporary_.string());
    fs::rename(temporary_, target_);
  }
  ~Writer()
  {
    std::error_code ignored;
    if (fs::exists(temporary_, ignored)) fs::remove(temporary_, ignored);
  }

private:
  fs::path target_, temporary_;
  std::ofstream out_;
};

class Reader {
public:
  explicit Reader(const fs::path& path)
    : path_(path), in_(path, std::ios::binary)
  {
    if (!in_) throw std::runtime_error(path.string() + ": cannot be opened");
  }
  template <class T>
  T value()
  {
    T v;
    in_.read(reinterpret_cast<char*>(&v), sizeof(T));
    if (!in_) throw std::runtime_error(path_.string() + ": truncated");
    return v;
  }
  template <class T>
  std::vector<T> vector(std::uint64_t limit = std::uint64_t(1) << 34)
  {
    const std::uint64_t n = value<std::uint64_t>();
    if (n > limit) throw std::runtime_error(path_.string() + ": corrupt (a list of " + std::to_string(n) + " entries)");
    std::vector<T> v(n);
    in_.read(reinterpret_cast<char*>(v.data()), std::streamsize(n * sizeof(T)));
    if (!in_) throw std::runtime_error(path_.string() + ": truncated");
    return v;
  }
  std::string string() { auto chars = vector<char>(1 << 20); return std::string(chars.begin(), chars.end()); }
  void magic(const char expected[8])
  {
    char m[8];
    in_.read(m, 8);
    if (!in_ || std::memcmp(m, expected, 8) != 0) throw std::runtime_error(path_.string() + ": not a BrainShift finite element file");
  }

private:
  fs::path path_;
  std::ifstream in_;
};
} // namespace

double tetrahedronStiffness(const double p[4][3], const ElasticMaterial& material, double K[144])
{
  // Shape function gradients from the inverse of the 4x4 [1 x y z] matrix: grad N_i = rows.
  const double a[3] = {p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
  const double b[3] = {p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
  const double c[3] = {p[3][0] - p[0][0], p[3][1] - p[0][1], p[3][2] - p[0][2]};
  const double det = a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0]);
  const double volume = det / 6.0;
  // J = [a b c] (columns); grad N_1..3 = rows of J^-1, grad N_0 = -(sum).
  double inv[3][3];
  inv[0][0] = (b[1] * c[2] - b[2] * c[1]) / det;
  inv[0][1] = (b[2] * c[0] - b[0] * c[2]) / det;
  inv[0][2] = (b[0] * c[1] - b[1] * c[0]) / det;
  inv[1][0] = (c[1] * a[2] - c[2] * a[1]) / det;
  inv[1][1] = (c[2] * a[0] - c[0] * a[2]) / det;
  inv[1][2] = (c[0] * a[1] - c[1] * a[0]) / det;
  inv[2][0] = (a[1] * b[2] - a[2] * b[1]) / det;
  inv[2][1] = (a[2] * b[0] - a[0] * b[2]) / det;
  inv[2][2] = (a[0] * b[1] - a[1] * b[0]) / det;
  double grad[4][3];
  for (int k = 0; k < 3; ++k) {
    grad[1][k] = inv[0][k];
    grad[2][k] = inv[1][k];
    grad[3][k] = inv[2][k];
    grad[0][k] = -(grad[1][k] + grad[2][k] + grad[3][k]);
  }
  const double E = material.youngsModulus, nu = material.poissonRatio;
  const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu)), mu = E / (2 * (1 + nu));
  const double v = std::abs(volume);
  // K_ij (3x3 block) = V (lambda g_i g_j^T + mu (g_j g_i^T + (g_i . g_j) I)).
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      const double dot = grad[i][0] * grad[j][0] + grad[i][1] * grad[j][1] + grad[i][2] * grad[j][2];
      for (int r = 0; r < 3; ++r) {
        for (int s = 0; s < 3; ++s) {
          K[(3 * i + r) * 12 + 3 * j + s] =
            v * (lambda * grad[i][r] * grad[j][s] + mu * (grad[j][r] * grad[i][s] + (r == s ? dot : 0.0)));
        }
      }
    }
  }
  return volume;
}

void FiniteElementJob::validate() const
{
  auto fail = [](const std::string& message) { throw std::invalid_argument(message); };
  if (nodes.size() % 3 != 0 || nodes.empty()) fail("the job has no nodes (or a partial one)");
  if (tetrahedra.size() % 4 != 0 || tetrahedra.empty()) fail("the job has no tetrahedra (or a partial one)");
  if (materialOfTetrahedron.size() != tetrahedronCount()) fail("one material per tetrahedron is expected");
  if (materials.empty()) fail("the job has no materials");
  for (std::size_t m = 0; m < materials.size(); ++m) {
    const ElasticMaterial& mat = materials[m];
    if (!std::isfinite(mat.youngsModulus) || mat.youngsModulus <= 0) {
      fail("material " + std::to_string(m) + ": Young's modulus must be positive and finite");
    }
    if (!std::isfinite(mat.poissonRatio) || mat.poissonRatio < 0 || mat.poissonRatio >= 0.5) {
      fail("material " + std::to_string(m) + ": Poisson ratio " + numberText(mat.poissonRatio) + " is outside [0, 0.5)");
    }
  }
  for (double x : nodes) {
    if (!std::isfinite(x)) fail("a node has a non-finite coordinate");
  }
  const std::int64_t n = std::int64_t(nodeCount());
  for (std::size_t t = 0; t < tetrahedronCount(); ++t) {
    double p[4][3];
    for (int k = 0; k < 4; ++k) {
      const std::int32_t v = tetrahedra[4 * t + k];
      if (v < 0 || v >= n) fail("tetrahedron " + std::to_string(t) + " refers to node " + std::to_string(v) + ", which does not exist");
      for (int d = 0; d < 3; ++d) p[k][d] = nodes[3 * std::size_t(v) + d];
    }
    const std::int32_t m = materialOfTetrahedron[t];
    if (m < 0 || std::size_t(m) >= materials.size()) fail("tetrahedron " + std::to_string(t) + " has no material");
    const double a[3] = {p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]};
    const double b[3] = {p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]};
    const double c[3] = {p[3][0] - p[0][0], p[3][1] - p[0][1], p[3][2] - p[0][2]};
    const double volume = (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0])) / 6.0;
    if (!(volume > 0)) {
      fail("tetrahedron " + std::to_string(t) + " is inverted or flat (volume " + numberText(volume) + " mm^3)");
    }
  }
  if (fixedNodes.empty()) fail("no boundary conditions: the displacement is not determined (a singular system)");
  if (fixedDisplacements.size() != 3 * fixedNodes.size()) fail("three displacement components per fixed node are expected");
  std::set<std::int32_t> seen;
  for (std::int32_t v : fixedNodes) {
    if (v < 0 || v >= n) fail("boundary node " + std::to_string(v) + " does not exist");
    if (!seen.insert(v).second) fail("boundary node " + std::to_string(v) + " is given twice");
  }
  for (double d : fixedDisplacements) {
    if (!std::isfinite(d)) fail("a boundary displacement is not finite");
  }
  validateSoftConstraints(tetrahedronCount());
}

void FiniteElementJob::validateSoftConstraints(std::size_t tetrahedra) const
{
  auto fail = [](std::size_t i, const std::string& message) {
    throw std::invalid_argument("soft constraint " + std::to_string(i) + ": " + message);
  };
  for (std::size_t i = 0; i < softConstraints.size(); ++i) {
    const SoftConstraint& c = softConstraints[i];
    if (c.tetrahedron < 0 || std::size_t(c.tetrahedron) >= tetrahedra) fail(i, "its tetrahedron does not exist");
    double sum = 0;
    for (double w : c.weights) {
      if (!std::isfinite(w) || w < -1e-6 || w > 1 + 1e-6) fail(i, "a barycentric weight outside [0, 1]");
      sum += w;
    }
    if (std::abs(sum - 1) > 1e-6) fail(i, "its barycentric weights do not sum to 1");
    for (double t : c.target) {
      if (!std::isfinite(t)) fail(i, "its target displacement is not finite");
    }
    for (double s : c.stiffness) {
      if (!std::isfinite(s)) fail(i, "its stiffness is not finite");
    }
    if (c.stiffness[0] < 0 || c.stiffness[3] < 0 || c.stiffness[5] < 0) fail(i, "its stiffness has a negative diagonal");
  }
  const SoftConstraintRejection& r = rejection;
  if (r.rounds < 0 || r.rounds > 100) throw std::invalid_argument("soft constraint rejection: rounds must be 0 to 100");
  if (!(r.fractionPerRound >= 0 && r.fractionPerRound <= 1)) throw std::invalid_argument("soft constraint rejection: the fraction per round must be in [0, 1]");
  if (!(r.outlierFactor >= 0) || !std::isfinite(r.outlierFactor)) throw std::invalid_argument("soft constraint rejection: the outlier factor must be finite and >= 0");
  if (!(r.floorMm >= 0) || !std::isfinite(r.floorMm)) throw std::invalid_argument("soft constraint rejection: the floor must be finite and >= 0 mm");
}

std::array<double, 3> softConstraintResidual(const FiniteElementJob& mesh, const SoftConstraint& constraint,
                                             const std::vector<double>& displacements)
{
  std::array<double, 3> r{-constraint.target[0], -constraint.target[1], -constraint.target[2]};
  for (std::size_t k = 0; k < 4; ++k) {
    const std::size_t node = std::size_t(mesh.tetrahedra[4 * std::size_t(constraint.tetrahedron) + k]);
    for (std::size_t d = 0; d < 3; ++d) r[d] += constraint.weights[k] * displacements[3 * node + d];
  }
  return r;
}

void writeFiniteElementJob(const FiniteElementJob& job, const fs::path& path)
{
  Writer w(path);
  w.raw(JobMagic, 8);
  w.vector(job.nodes);
  w.vector(job.tetrahedra);
  w.vector(job.materialOfTetrahedron);
  std::vector<double> materials;
  for (const auto& m : job.materials) {
    materials.push_back(m.youngsModulus);
    materials.push_back(m.poissonRatio);
  }
  w.vector(materials);
  w.vector(job.fixedNodes);
  w.vector(job.fixedDisplacements);
  w.string(job.solverOptions);
  std::vector<std::int32_t> tetrahedra;
  std::vector<double> values;
  tetrahedra.reserve(job.softConstraints.size());
  values.reserve(SoftConstraintValues * job.softConstraints.size());
  for (const SoftConstraint& c : job.softConstraints) {
    tetrahedra.push_back(c.tetrahedron);
    values.insert(values.end(), c.weights.begin(), c.weights.end());
    values.insert(values.end(), c.target.begin(), c.target.end());
    values.insert(values.end(), c.stiffness.begin(), c.stiffness.end());
  }
  w.vector(tetrahedra);
  w.vector(values);
  w.value(job.rejection.rounds);
  w.value(job.rejection.fractionPerRound);
  w.value(job.rejection.outlierFactor);
  w.value(job.rejection.floorMm);
  w.commit();
}

FiniteElementJob readFiniteElementJob(const fs::path& path)
{
  Reader r(path);
  r.magic(JobMagic);
  FiniteElementJob job;
  job.nodes = r.vector<double>();
  job.tetrahedra = r.vector<std::int32_t>();
  job.materialOfTetrahedron = r.vector<std::int32_t>();
  const auto materials = r.vector<double>();
  for (std::size_t i = 0; i + 1 < materials.size(); i += 2) job.materials.push_back({materials[i], materials[i + 1]});
  job.fixedNodes = r.vector<std::int32_t>();
  job.fixedDisplacements = r.vector<double>();
  job.solverOptions = r.string();
  const auto tetrahedra = r.vector<std::int32_t>();
  const auto values = r.vector<double>();
  if (values.size() != SoftConstraintValues * tetrahedra.size()) {
    throw std::runtime_error(path.string() + ": corrupt (soft constraints of the wrong size)");
  }
  job.softConstraints.resize(tetrahedra.size());
  for (std::size_t i = 0; i < tetrahedra.size(); ++i) {
    SoftConstraint& c = job.softConstraints[i];
    const double* v = values.data() + SoftConstraintValues * i;
    c.tetrahedron = tetrahedra[i];
    std::copy(v, v + 4, c.weights.begin());
    std::copy(v + 4, v + 7, c.target.begin());
    std::copy(v + 7, v + 13, c.stiffness.begin());
  }
  job.rejection.rounds = r.value<int>();
  job.rejection.fractionPerRound = r.value<double>();
  job.rejection.outlierFactor = r.value<double>();
  job.rejection.floorMm = r.value<double>();
  return job;
}

void writeFiniteElementResult(const FiniteElementResult& result, const fs::path& path)
{
  Writer w(path);
  w.raw(ResultMagic, 8);
  w.vector(result.displacements);
  w.value(result.equations);
  w.value(result.ranks);
  w.value(result.iterations);
  w.value(result.relativeResidual);
  w.value(result.convergedReason);
  w.value(result.assemblySeconds);
  w.value(result.setupSeconds);
  w.value(result.solveSeconds);
  w.string(result.solver);
  w.string(result.partitioner);
  w.vector(result.tetrahedraPerRank);
  w.vector(result.softConstraintKept);
  w.vector(result.softConstraintMisfitMm);
  w.vector(result.keptPerRound);
  w.vector(result.rmsMisfitPerRoundMm);
  w.commit();
}

FiniteElementResult readFiniteElementResult(const fs::path& path)
{
  Reader r(path);
  r.magic(ResultMagic);
  FiniteElementResult result;
  result.displacements = r.vector<double>();
  result.equations = r.value<std::int64_t>();
  result.ranks = r.value<int>();
  result.iterations = r.value<int>();
  result.relativeResidual = r.value<double>();
  result.convergedReason = r.value<int>();
  result.assemblySeconds = r.value<double>();
  result.setupSeconds = r.value<double>();
  result.solveSeconds = r.value<double>();
  result.solver = r.string();
  result.partitioner = r.string();
  result.tetrahedraPerRank = r.vector<std::int64_t>();
  result.softConstraintKept = r.vector<std::uint8_t>();
  result.softConstraintMisfitMm = r.vector<double>();
  result.keptPerRound = r.vector<std::int64_t>();
  result.rmsMisfitPerRoundMm = r.vector<double>();
  return result;
}

} // namespace brainshift
