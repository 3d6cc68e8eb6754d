#include "FiniteElementTruth.h"

#include "BrainShiftErrors.h"
#include "ExternalProgram.h"
#include "CgalLabelMapMesher.h"
#include "NumberText.h"

#include <itkImageRegionIteratorWithIndex.h>
#include <vtkCellArray.h>
#include <vtkGenericCell.h>
#include <vtkNew.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkStaticCellLocator.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <deque>
#include <fstream>
#include <iomanip>
#include <map>
#include <numeric>
#include <sstream>
#include <string>

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

namespace brainshift {
namespace fs = std::filesystem;

namespace {
using Vec3 = std::array<double, 3>;
using Mat3 = std::array<Vec3, 3>; // rows
Vec3 operator+(const Vec3& a, const Vec3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
Vec3 operator-(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3 operator*(double s, const Vec3& a) { return {s * a[0], s * a[1], s * a[2]}; }
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double norm(const Vec3& a) { return std::sqrt(dot(a, a)); }
Vec3 cross(const Vec3& a, const Vec3& b) { return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]}; }
Vec3 times(const Mat3& m, const Vec3& v) { return {dot(m[0], v), dot(m[1], v), dot(m[2], v)}; }

/// The inverse of the matrix whose COLUMNS are a, b, c (as rows of the result's inverse), or nothing when singular.
std::optional<Mat3> inverseOfColumns(const Vec3& a, const Vec3& b, const Vec3& c)
{
  const double det = dot(a, cross(b, c));
  const double scale = norm(a) * norm(b) * norm(c);
  if (!(std::abs(det) > 1e-12 * scale) || scale == 0) return std::nullopt;
  // inverse of [a b c]: rows (b x c, c x a, a x b) / det.
  return Mat3{(1 / det) * cross(b, c), (1 / det) * cross(c, a), (1 / det) * cross(a, b)};
}

// Tissue materials (Young's modulus in kPa, Poisson's ratio), from the literature on brain shift, and
// deliberately not BrainShift's defaults (Resources/Configurations/default.json: 3 / 0.45, 0.1 / 0.3,
// 10 / 0.45): a truth that shared the method's materials would reward it for its own assumptions.
//  - parenchyma: E 3 kPa, nu 0.49: Wittek, Hawkins, Miller, Biomech Model Mechanobiol 8:77-84 (2009), and
//    Miller & Chinzei's low-strain-rate shear modulus of about 1 kPa (E = 2 mu (1 + nu));
//  - ventricles: a very soft compressible solid standing in for CSF, E 10 Pa, nu 0.1: Wittek et al.,
//    Prog Biophys Mol Biol 103:292-303 (2010); Joldes et al., Med Image Anal 13:912-919 (2009);
//  - tumour: twice as stiff as parenchyma, E 6 kPa, nu 0.49: Wittek, Miller, Kikinis, Warfield,
//    J Biomech 40:919-929 (2007).
// With the loads prescribed as displacements only the ratios and Poisson's ratios shape the result.
struct Material {
  int label;
  const char* name;
  double youngsModulusKpa, poissonRatio;
};
constexpr Material materials[] = {{2, "Parenchyma", 3.0, 0.49}, {3, "Ventricles", 0.01, 0.1}, {4, "Tumour", 6.0, 0.49}};

// C3D10: corners 0-3, then the middles of the edges 01 12 20 03 13 23 (CalculiX's shape10tet.f).
constexpr int edgeCorners[6][2] = {{0, 1}, {1, 2}, {2, 0}, {0, 3}, {1, 3}, {2, 3}};
// Each quadratic element as 8 straight tetrahedra of its 10 nodes: the 4 corner ones and the octahedron
// cut along its 01-23 diagonal.
constexpr int subTetrahedra[8][4] = {{0, 4, 6, 7}, {4, 1, 5, 8}, {6, 5, 2, 9}, {7, 8, 9, 3},
                                     {4, 9, 5, 6}, {4, 9, 6, 7}, {4, 9, 7, 8}, {4, 9, 8, 5}};
// Natural coordinates (xi, eta, zeta) of the 10 nodes.
constexpr double naturalOf[10][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0.5, 0, 0},
                                     {0.5, 0.5, 0}, {0, 0.5, 0}, {0, 0, 0.5}, {0.5, 0, 0.5}, {0, 0.5, 0.5}};

/// CalculiX's C3D10 shape functions at natural coordinates (xi, eta, zeta), and their derivatives.
void quadraticShape(const Vec3& s, double N[10], double dN[10][3] = nullptr)
{
  const double xi = s[0], et = s[1], ze = s[2], a = 1 - xi - et - ze;
  N[0] = a * (2 * a - 1), N[1] = xi * (2 * xi - 1), N[2] = et * (2 * et - 1), N[3] = ze * (2 * ze - 1);
  N[4] = 4 * xi * a, N[5] = 4 * xi * et, N[6] = 4 * et * a, N[7] = 4 * ze * a, N[8] = 4 * xi * ze, N[9] = 4 * et * ze;
  if (!dN) return;
  const double d[10][3] = {{1 - 4 * a, 1 - 4 * a, 1 - 4 * a},
                           {4 * xi - 1, 0, 0},
                           {0, 4 * et - 1, 0},
                           {0, 0, 4 * ze - 1},
                           {4 * (a - xi), -4 * xi, -4 * xi},
                           {4 * et, 4 * xi, 0},
                           {-4 * et, 4 * (a - et), -4 * et},
                           {-4 * ze, -4 * ze, 4 * (a - ze)},
                           {4 * ze, 0, 4 * xi},
                           {0, 4 * ze, 4 * et}};
  std::copy(&d[0][0], &d[0][0] + 30, &dN[0][0]);
}

std::string lastLines(const std::string& text, std::size_t count)
{
  std::size_t at = text.size();
  for (std::size_t n = 0; n <= count && at > 0; ++n) {
    const std::size_t previous = text.rfind('\n', at - 1);
    if (previous == std::string::npos) return text;
    at = previous;
  }
  return text.substr(at + 1);
}

/// Several lines as one (the command line prints one line per error): line breaks become " | ".
std::string oneLine(std::string text)
{
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r')) text.pop_back();
  std::string joined;
  for (char c : text) joined += c == '\n' ? std::string(" | ") : std::string(1, c);
  return joined;
}

/// The work folder: the caller's (kept), or a fresh temporary one removed when this goes out of scope.
struct WorkFolder {
  fs::path path;
  bool temporary = false;
  explicit WorkFolder(const fs::path& requested)
  {
    static std::atomic<int> counter{0};
    temporary = requested.empty();
    path = temporary ? fs::temp_directory_path() / ("brainshift-fe-truth-" + std::to_string(::getpid()) + "-" + std::to_string(counter++))
                     : requested;
    std::error_code error;
    fs::create_directories(path, error);
    if (error) throw InputError(path.string() + ": cannot create the finite element work folder: " + error.message());
  }
  ~WorkFolder()
  {
    std::error_code ignored;
    if (temporary) fs::remove_all(path, ignored);
  }
};

// ---- The mesh ----------------------------------------------------------------------------------

using Face = std::array<std::int64_t, 3>; // sorted corner ids
Face faceKey(std::int64_t a, std::int64_t b, std::int64_t c)
{
  Face f{a, b, c};
  std::sort(f.begin(), f.end());
  return f;
}

/// The elements of the largest piece connected through shared faces (a piece joined by an edge or a
/// node only would be a mechanism); the others are dropped.
std::vector<std::size_t> largestFaceConnectedPiece(const TetrahedralMeshArrays& mesh)
{
  const std::size_t count = mesh.tetrahedra.size();
  std::vector<std::size_t> parent(count);
  std::iota(parent.begin(), parent.end(), 0);
  auto root = [&](std::size_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  std::map<Face, std::size_t> firstWithFace;
  for (std::size_t t = 0; t < count; ++t) {
    const auto& v = mesh.tetrahedra[t];
    for (int k = 0; k < 4; ++k) {
      const Face f = faceKey(v[(k + 1) % 4], v[(k + 2) % 4], v[(k + 3) % 4]);
      auto [at, inserted] = firstWithFace.emplace(f, t);
      if (!inserted) parent[root(t)] = root(at->second);
    }
  }
  std::map<std::size_t, std::size_t> size;
  for (std::size_t t = 0; t < count; ++t) ++size[root(t)];
  std::size_t best = 0, bestSize = 0;
  for (const auto& [r, n] : size) {
    if (n > bestSize) best = r, bestSize = n;
  }
  std::vector<std::size_t> kept;
  for (std::size_t t = 0; t < count; ++t) {
    if (root(t) == best) kept.push_back(t);
  }
  return kept;
}

/// The kept linear tetrahedra made quadratic: corners renumbered in order of first use, then one node at
/// the middle of every edge, shared by all the elements around the edge.
void makeQuadratic(const TetrahedralMeshArrays& linear, const std::vector<std::size_t>& kept, FiniteElementTruthModel& model)
{
  std::map<std::int64_t, std::int64_t> cornerId;
  for (std::size_t t : kept) {
    for (long long v : linear.tetrahedra[t]) {
      cornerId.emplace(v, -1);
    }
  }
  for (std::size_t t : kept) { // ids in order of first use: independent of the map's order
    for (long long v : linear.tetrahedra[t]) {
      auto& id = cornerId[v];
      if (id < 0) {
        id = std::int64_t(model.nodes.size());
        model.nodes.push_back(linear.points[std::size_t(v)]);
      }
    }
  }
  std::map<std::pair<std::int64_t, std::int64_t>, std::int64_t> middleOf;
  for (std::size_t t : kept) {
    std::array<std::int64_t, 10> element{};
    for (int k = 0; k < 4; ++k) element[std::size_t(k)] = cornerId[linear.tetrahedra[t][std::size_t(k)]];
    for (int e = 0; e < 6; ++e) {
      const std::int64_t a = element[std::size_t(edgeCorners[e][0])], b = element[std::size_t(edgeCorners[e][1])];
      auto [at, inserted] = middleOf.emplace(std::minmax(a, b), std::int64_t(model.nodes.size()));
      if (inserted) model.nodes.push_back(0.5 * (model.nodes[std::size_t(a)] + model.nodes[std::size_t(b)]));
      element[std::size_t(4 + e)] = at->second;
    }
    model.elements.push_back(element);
    model.labels.push_back(linear.labels[t]);
  }
}

/// The faces that belong to one element only, oriented outward, with their mid-edge nodes.
void findBoundaryFaces(FiniteElementTruthModel& model)
{
  // The local mid-edge node between two corners (edgeCorners).
  constexpr int middleOf[4][4] = {{0, 4, 6, 7}, {4, 0, 5, 8}, {6, 5, 0, 9}, {7, 8, 9, 0}};
  auto middle = [&](int a, int b) { return std::size_t(middleOf[a][b]); };
  std::map<Face, std::pair<std::size_t, int>> faces; // face -> (element, opposite corner); count by erasing
  std::map<Face, int> uses;
  for (std::size_t t = 0; t < model.elements.size(); ++t) {
    const auto& el = model.elements[t];
    for (int k = 0; k < 4; ++k) {
      const Face f = faceKey(el[std::size_t((k + 1) % 4)], el[std::size_t((k + 2) % 4)], el[std::size_t((k + 3) % 4)]);
      faces.emplace(f, std::make_pair(t, k));
      ++uses[f];
    }
  }
  for (const auto& [f, where] : faces) {
    if (uses[f] != 1) continue;
    const auto& el = model.elements[where.first];
    const int k = where.second;
    int a = (k + 1) % 4, b = (k + 2) % 4, c = (k + 3) % 4;
    const Vec3& pa = model.nodes[std::size_t(el[std::size_t(a)])];
    const Vec3 n = cross(model.nodes[std::size_t(el[std::size_t(b)])] - pa, model.nodes[std::size_t(el[std::size_t(c)])] - pa);
    if (dot(n, model.nodes[std::size_t(el[std::size_t(k)])] - pa) > 0) std::swap(b, c); // away from the opposite corner
    model.boundaryFaces.push_back({el[std::size_t(a)], el[std::size_t(b)], el[std::size_t(c)], el[middle(a, b)],
                                   el[middle(b, c)], el[middle(c, a)]});
  }
}

/// Outward unit normals of the surface nodes: the area-weighted normals of the faces around them.
void computeNormals(FiniteElementTruthModel& model)
{
  model.normals.assign(model.nodes.size(), Vec3{0, 0, 0});
  for (const auto& f : model.boundaryFaces) {
    const Vec3& a = model.nodes[std::size_t(f[0])];
    const Vec3 areaNormal = cross(model.nodes[std::size_t(f[1])] - a, model.nodes[std::size_t(f[2])] - a); // 2 x area
    for (std::int64_t v : f) model.normals[std::size_t(v)] = model.normals[std::size_t(v)] + areaNormal;
  }
  for (Vec3& n : model.normals) {
    const double length = norm(n);
    if (length > 0) n = (1 / length) * n;
  }
}

/// Cap (prescribed sinking), skull base (fixed), sliding: see the header.
void assignRoles(FiniteElementTruthModel& model, const FiniteElementTruthParameters& P)
{
  const std::size_t count = model.nodes.size();
  model.roles.assign(count, FiniteElementTruthModel::Role::Interior);
  model.prescribed.assign(count, Vec3{0, 0, 0});
  std::vector<char> onSurface(count, 0);
  for (const auto& f : model.boundaryFaces) {
    for (std::int64_t v : f) onSurface[std::size_t(v)] = 1;
  }
  double zMin = INFINITY, zMax = -INFINITY;
  for (std::size_t v = 0; v < count; ++v) {
    if (!onSurface[v]) continue;
    zMin = std::min(zMin, model.nodes[v][2]);
    zMax = std::max(zMax, model.nodes[v][2]);
  }
  const double baseTop = zMin + P.skullBaseFraction * (zMax - zMin);
  const Vec3& axis = P.craniotomyAxis;
  for (std::size_t v = 0; v < count; ++v) {
    if (!onSurface[v]) continue;
    const Vec3 d = model.nodes[v] - P.craniotomyCentre;
    const double along = dot(d, axis), r2 = std::max(dot(d, d) - along * along, 0.0);
    using Role = FiniteElementTruthModel::Role;
    if (r2 < P.openingRadiusMm * P.openingRadiusMm && along > -P.openingRadiusMm && dot(model.normals[v], axis) > 0) {
      model.roles[v] = Role::Loaded;
      model.prescribed[v] = (-P.shiftMm * std::exp(-r2 / (2 * P.lateralSigmaMm * P.lateralSigmaMm))) * axis;
    } else {
      model.roles[v] = model.nodes[v][2] <= baseTop ? Role::Fixed : Role::Sliding;
    }
  }
}

// ---- CalculiX ----------------------------------------------------------------------------------

void writeDeck(const FiniteElementTruthModel& model, const fs::path& inp)
{
  std::ofstream out(inp);
  // ccx reads a number from at most 20 characters: 13 significant digits, "-1.234567890123e-18".
  out << std::scientific << std::setprecision(12);
  out << "** BrainShift finite element truth: " << model.nodes.size() << " nodes, " << model.elements.size()
      << " C3D10; mm, mN, kPa\n*NODE, NSET=Nall\n";
  for (std::size_t v = 0; v < model.nodes.size(); ++v) {
    out << v + 1 << ", " << model.nodes[v][0] << ", " << model.nodes[v][1] << ", " << model.nodes[v][2] << '\n';
  }
  for (const Material& m : materials) {
    bool any = false;
    for (std::size_t t = 0; t < model.elements.size(); ++t) {
      if (model.labels[t] != m.label) continue;
      if (!any) out << "*ELEMENT, TYPE=C3D10, ELSET=" << m.name << '\n';
      any = true;
      out << t + 1; // 8 ids on the first line, 2 on a continuation line (at most 16 entries a line)
      for (int k = 0; k < 10; ++k) out << (k == 8 ? ",\n" : ", ") << model.elements[t][std::size_t(k)] + 1;
      out << '\n';
    }
    if (!any) continue;
    out << "*MATERIAL, NAME=" << m.name << "\n*ELASTIC\n" << m.youngsModulusKpa << ", " << m.poissonRatio << '\n'
        << "*SOLID SECTION, ELSET=" << m.name << ", MATERIAL=" << m.name << '\n';
  }
  // Sliding: u . n = 0; the dependent (first) degree of freedom is the normal's largest component.
  for (std::size_t v = 0; v < model.nodes.size(); ++v) {
    if (model.roles[v] != FiniteElementTruthModel::Role::Sliding) continue;
    const Vec3& n = model.normals[v];
    int order[3] = {0, 1, 2};
    std::stable_sort(order, order + 3, [&](int a, int b) { return std::abs(n[std::size_t(a)]) > std::abs(n[std::size_t(b)]); });
    out << "*EQUATION\n3\n";
    for (int k = 0; k < 3; ++k) out << (k ? ", " : "") << v + 1 << ", " << order[k] + 1 << ", " << n[std::size_t(order[k])];
    out << '\n';
  }
  out << "*STEP\n*STATIC\n*BOUNDARY\n";
  for (std::size_t v = 0; v < model.nodes.size(); ++v) {
    const auto role = model.roles[v];
    if (role == FiniteElementTruthModel::Role::Fixed) out << v + 1 << ", 1, 3, 0.0\n";
    if (role != FiniteElementTruthModel::Role::Loaded) continue;
    for (int d = 0; d < 3; ++d) out << v + 1 << ", " << d + 1 << ", " << d + 1 << ", " << model.prescribed[v][std::size_t(d)] << '\n';
  }
  out << "*NODE PRINT, NSET=Nall\nU\n*END STEP\n";
  out.close();
  if (!out) throw MethodError(inp.string() + ": cannot write the CalculiX input deck");
}

/// Runs `ccx -i name` in `folder` on one thread; returns its wall time. MethodError with the end of its output on failure.
double runCcx(const fs::path& ccx, const fs::path& folder, const std::string& name, double& peakMemoryMb)
{
  const fs::path log = folder / "ccx.log";
  const std::string command = "cd " + shellQuoted(folder.string()) +
                              " && OMP_NUM_THREADS=1 CCX_NPROC_STIFFNESS=1 CCX_NPROC_EQUATION_SOLVER=1 CCX_NPROC_RESULTS=1 " +
                              shellQuoted(ccx.string()) + " -i " + shellQuoted(name) + " > ccx.log 2>&1 < /dev/null";
  const auto start = std::chrono::steady_clock::now();
  const int status = std::system(command.c_str());
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  struct rusage usage {};
  if (::getrusage(RUSAGE_CHILDREN, &usage) == 0) peakMemoryMb = double(usage.ru_maxrss) / 1024.0; // the largest child so far
  std::ifstream in(log);
  std::stringstream output;
  output << in.rdbuf();
  const std::string text = output.str();
  const bool exited = status != -1 && WIFEXITED(status);
  const int code = exited ? WEXITSTATUS(status) : -1;
  // ccx exits 0 even on some errors: its own markers decide too.
  if (!exited || code != 0 || text.find("*ERROR") != std::string::npos || text.find("Job finished") == std::string::npos) {
    throw MethodError("finite element truth: ccx failed (exit code " + std::to_string(code) + ") on " + (folder / (name + ".inp")).string() +
                      "; the end of its output: " + oneLine(lastLines(text, 5)));
  }
  return seconds;
}

/// The displacements of *NODE PRINT U in `dat`: "displacements (vx,vy,vz) for set NALL ..." then "id ux uy uz".
void readDisplacements(const fs::path& dat, FiniteElementTruthModel& model)
{
  std::ifstream in(dat);
  if (!in) throw MethodError(dat.string() + ": ccx wrote no results file");
  model.displacements.assign(model.nodes.size(), Vec3{0, 0, 0});
  std::vector<char> seen(model.nodes.size(), 0);
  std::size_t count = 0;
  bool inBlock = false;
  std::string line;
  while (std::getline(in, line)) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    if (line.find("displacements") != std::string::npos) {
      inBlock = true;
      continue;
    }
    if (line.find_first_of("abcdfghijklmnopqrstuvwxyz(") != std::string::npos) inBlock = false; // 'e' is an exponent
    if (!inBlock) continue;
    std::istringstream fields(line);
    long long id = 0;
    Vec3 u;
    if (!(fields >> id >> u[0] >> u[1] >> u[2]) || id < 1 || std::size_t(id) > model.nodes.size() || seen[std::size_t(id - 1)] ||
        !std::isfinite(u[0] + u[1] + u[2])) {
      throw MethodError(dat.string() + ": unreadable displacement line '" + line + "'");
    }
    seen[std::size_t(id - 1)] = 1;
    ++count;
    model.displacements[std::size_t(id - 1)] = u;
  }
  if (count != model.nodes.size()) {
    throw MethodError(dat.string() + ": " + std::to_string(count) + " of " + std::to_string(model.nodes.size()) + " displacements");
  }
}

/// Elements whose deformed Jacobian is not positive at a corner or at the centroid: where the linear
/// solution folds, the forward map cannot be inverted uniquely.
std::size_t countInvertedElements(const FiniteElementTruthModel& model)
{
  const Vec3 samples[5] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {0.25, 0.25, 0.25}};
  std::size_t inverted = 0;
  for (const auto& el : model.elements) {
    bool folded = false;
    for (const Vec3& s : samples) {
      double N[10], dN[10][3];
      quadraticShape(s, N, dN);
      Vec3 columns[3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}}; // d x / d s_j
      for (int k = 0; k < 10; ++k) {
        const Vec3 x = model.nodes[std::size_t(el[std::size_t(k)])] + model.displacements[std::size_t(el[std::size_t(k)])];
        for (int j = 0; j < 3; ++j) columns[j] = columns[j] + dN[k][j] * x;
      }
      folded = folded || dot(columns[0], cross(columns[1], columns[2])) <= 0;
    }
    inverted += folded;
  }
  return inverted;
}

// ---- Point location ----------------------------------------------------------------------------

/// Elements listed in the cubes of a uniform grid that their bounding boxes touch.
struct BucketGrid {
  Vec3 origin{};
  double cell = 1;
  std::array<long, 3> dims{1, 1, 1};
  std::vector<std::vector<std::uint32_t>> buckets;

  void build(const std::vector<std::array<Vec3, 2>>& boxes, double cellSize)
  {
    Vec3 lo{INFINITY, INFINITY, INFINITY}, hi{-INFINITY, -INFINITY, -INFINITY};
    for (const auto& b : boxes) {
      for (int d = 0; d < 3; ++d) lo[std::size_t(d)] = std::min(lo[std::size_t(d)], b[0][std::size_t(d)]), hi[std::size_t(d)] = std::max(hi[std::size_t(d)], b[1][std::size_t(d)]);
    }
    cell = cellSize, origin = lo;
    for (int d = 0; d < 3; ++d) dims[std::size_t(d)] = std::max(1L, long(std::ceil((hi[std::size_t(d)] - lo[std::size_t(d)]) / cell)) + 1);
    buckets.assign(std::size_t(dims[0] * dims[1] * dims[2]), {});
    for (std::size_t e = 0; e < boxes.size(); ++e) {
      const auto a = indexOf(boxes[e][0]), b = indexOf(boxes[e][1]);
      for (long k = a[2]; k <= b[2]; ++k)
        for (long j = a[1]; j <= b[1]; ++j)
          for (long i = a[0]; i <= b[0]; ++i) buckets[std::size_t(i + dims[0] * (j + dims[1] * k))].push_back(std::uint32_t(e));
    }
  }
  std::array<long, 3> indexOf(const Vec3& p) const
  {
    std::array<long, 3> index{};
    for (int d = 0; d < 3; ++d) index[std::size_t(d)] = std::clamp(long(std::floor((p[std::size_t(d)] - origin[std::size_t(d)]) / cell)), 0L, dims[std::size_t(d)] - 1);
    return index;
  }
  const std::vector<std::uint32_t>* at(const Vec3& p) const
  {
    for (int d = 0; d < 3; ++d) {
      if (p[std::size_t(d)] < origin[std::size_t(d)] || p[std::size_t(d)] > origin[std::size_t(d)] + cell * double(dims[std::size_t(d)])) return nullptr;
    }
    const auto i = indexOf(p);
    return &buckets[std::size_t(i[0] + dims[0] * (i[1] + dims[1] * i[2]))];
  }
};

constexpr double insideTolerance = 1e-9;
} // namespace

void FiniteElementTruthParameters::validate() const
{
  const double axisLength = norm(craniotomyAxis);
  if (std::abs(axisLength - 1) > 1e-3) {
    throw InputError("finite element truth: the craniotomy axis must be a unit vector (its length is " + std::to_string(axisLength) + ")");
  }
  auto positive = [](double value, const char* name) {
    if (!(value > 0) || !std::isfinite(value)) throw InputError(std::string("finite element truth: ") + name + " must be positive, not " + std::to_string(value));
  };
  positive(lateralSigmaMm, "lateralSigmaMm");
  positive(openingRadiusMm, "openingRadiusMm");
  positive(elementSizeMm, "elementSizeMm");
  positive(fieldTaperMm, "fieldTaperMm");
  if (!(shiftMm >= 0) || !std::isfinite(shiftMm)) throw InputError("finite element truth: shiftMm must be 0 or more, not " + numberText(shiftMm));
  if (!(skullBaseFraction > 0 && skullBaseFraction < 1)) {
    throw InputError("finite element truth: skullBaseFraction must be in (0, 1), not " + numberText(skullBaseFraction));
  }
}

FiniteElementTruthModel buildFiniteElementTruthModel(const LabelImage& preopLabels, const FiniteElementTruthParameters& P,
                                                     FiniteElementTruthFigures* figures)
{
  P.validate();
#ifndef BRAINSHIFT_HAVE_CGAL
  (void)preopLabels;
  (void)figures;
  throw NotAvailableError("finite element truth: needs the CGAL Mesh_3 mesher; BrainShift was built without CGAL (install libcgal-dev)");
#else
  const auto start = std::chrono::steady_clock::now();
  MeshingParameters meshing;
  meshing.backend = MeshingBackend::Cgal;
  meshing.resolutionMm = P.elementSizeMm;
  meshing.labels = {2, 3, 4};
  meshing.validate(preopLabels);
  const TetrahedralMeshArrays linear = meshLabelMapWithCgal(preopLabels, meshing);
  const std::vector<std::size_t> kept = largestFaceConnectedPiece(linear);
  if (kept.empty()) throw InputError("finite element truth: CGAL made no elements of the brain (labels 2, 3, 4)");
  FiniteElementTruthModel model;
  makeQuadratic(linear, kept, model);
  findBoundaryFaces(model);
  computeNormals(model);
  assignRoles(model, P);
  if (figures) {
    figures->nodes = model.nodes.size();
    figures->elements = model.elements.size();
    figures->droppedElements = linear.tetrahedra.size() - kept.size();
    figures->meshSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    figures->slidingNodes = figures->fixedNodes = figures->loadedNodes = 0;
    for (auto role : model.roles) {
      figures->slidingNodes += role == FiniteElementTruthModel::Role::Sliding;
      figures->fixedNodes += role == FiniteElementTruthModel::Role::Fixed;
      figures->loadedNodes += role == FiniteElementTruthModel::Role::Loaded;
    }
  }
  return model;
#endif
}

void solveFiniteElementTruthModel(FiniteElementTruthModel& model, const FiniteElementTruthParameters& P, FiniteElementTruthFigures& figures)
{
  const fs::path ccx = findOnPath("ccx");
  if (ccx.empty()) throw NotAvailableError("finite element truth: CalculiX (ccx) is not on PATH: install the Debian package calculix-ccx");
  const WorkFolder folder(P.workFolder);
  const std::string name = "truth";
  writeDeck(model, folder.path / (name + ".inp"));
  figures.ccxSeconds = runCcx(ccx, folder.path, name, figures.ccxPeakMemoryMb);
  readDisplacements(folder.path / (name + ".dat"), model);
  figures.maxDisplacementMm = 0;
  for (const Vec3& u : model.displacements) figures.maxDisplacementMm = std::max(figures.maxDisplacementMm, norm(u));
  figures.invertedElements = countInvertedElements(model);
}

// ---- Interpolation and inversion ---------------------------------------------------------------

struct FiniteElementDisplacement::Impl {
  const FiniteElementTruthModel& model;
  std::vector<Mat3> toNatural; // per element: inverse of [p1 - p0, p2 - p0, p3 - p0]
  BucketGrid undeformed, deformed;

  explicit Impl(const FiniteElementTruthModel& m) : model(m)
  {
    if (model.displacements.size() != model.nodes.size()) throw MethodError("finite element truth: the model has not been solved");
    std::vector<std::array<Vec3, 2>> before, after;
    double meanEdge = 0;
    for (const auto& el : model.elements) {
      const Vec3& p0 = node(el[0]);
      const auto inverse = inverseOfColumns(node(el[1]) - p0, node(el[2]) - p0, node(el[3]) - p0);
      if (!inverse) throw MethodError("finite element truth: a flat element in the mesh");
      toNatural.push_back(*inverse);
      std::array<Vec3, 2> box{node(el[0]), node(el[0])}, moved{box};
      for (std::int64_t v : el) {
        const Vec3 p = node(v), q = p + model.displacements[std::size_t(v)];
        for (int d = 0; d < 3; ++d) {
          box[0][std::size_t(d)] = std::min(box[0][std::size_t(d)], p[std::size_t(d)]), box[1][std::size_t(d)] = std::max(box[1][std::size_t(d)], p[std::size_t(d)]);
          moved[0][std::size_t(d)] = std::min(moved[0][std::size_t(d)], q[std::size_t(d)]), moved[1][std::size_t(d)] = std::max(moved[1][std::size_t(d)], q[std::size_t(d)]);
        }
      }
      meanEdge += norm(node(el[1]) - p0) / double(model.elements.size());
      before.push_back(box);
      after.push_back(moved);
    }
    undeformed.build(before, std::max(meanEdge, 1.0));
    deformed.build(after, std::max(meanEdge, 1.0));
  }
  const Vec3& node(std::int64_t v) const { return model.nodes[std::size_t(v)]; }

  Vec3 natural(std::size_t e, const Vec3& X) const { return times(toNatural[e], X - node(model.elements[e][0])); }
  static double minimumBarycentric(const Vec3& s) { return std::min({1 - s[0] - s[1] - s[2], s[0], s[1], s[2]}); }

  /// The element containing X (trying `hint` first), or the hint when none does.
  std::optional<std::size_t> locate(const Vec3& X, std::optional<std::size_t> hint = std::nullopt) const
  {
    if (hint && minimumBarycentric(natural(*hint, X)) >= -insideTolerance) return hint;
    if (const auto* candidates = undeformed.at(X)) {
      for (std::uint32_t e : *candidates) {
        if (minimumBarycentric(natural(e, X)) >= -insideTolerance) return std::size_t(e);
      }
    }
    return hint;
  }
  Vec3 displacement(std::size_t e, const Vec3& X, Mat3* gradient = nullptr) const
  {
    double N[10], dN[10][3];
    quadraticShape(natural(e, X), N, gradient ? dN : nullptr);
    Vec3 u{0, 0, 0};
    Mat3 dUdS{}; // d u_i / d s_j
    for (int k = 0; k < 10; ++k) {
      const Vec3& uk = model.displacements[std::size_t(model.elements[e][std::size_t(k)])];
      u = u + N[k] * uk;
      if (!gradient) continue;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) dUdS[std::size_t(i)][std::size_t(j)] += uk[std::size_t(i)] * dN[k][j];
    }
    if (gradient) { // du/dX = du/ds ds/dX, ds/dX = toNatural
      const Mat3& S = toNatural[e];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) (*gradient)[std::size_t(i)][std::size_t(j)] = dUdS[std::size_t(i)][0] * S[0][std::size_t(j)] + dUdS[std::size_t(i)][1] * S[1][std::size_t(j)] + dUdS[std::size_t(i)][2] * S[2][std::size_t(j)];
    }
    return u;
  }

  /// The element and preoperative point of x' from the deformed straight sub-tetrahedra, or nothing.
  std::optional<std::pair<std::size_t, Vec3>> deformedGuess(const Vec3& x) const
  {
    const auto* candidates = deformed.at(x);
    if (!candidates) return std::nullopt;
    for (std::uint32_t e : *candidates) {
      const auto& el = model.elements[e];
      for (const auto& sub : subTetrahedra) {
        Vec3 q[4];
        for (int k = 0; k < 4; ++k) q[k] = node(el[std::size_t(sub[k])]) + model.displacements[std::size_t(el[std::size_t(sub[k])])];
        const auto inverse = inverseOfColumns(q[1] - q[0], q[2] - q[0], q[3] - q[0]);
        if (!inverse) continue;
        const Vec3 l = times(*inverse, x - q[0]);
        if (minimumBarycentric(l) < -insideTolerance) continue;
        const double weights[4] = {1 - l[0] - l[1] - l[2], l[0], l[1], l[2]};
        Vec3 X{0, 0, 0};
        for (int k = 0; k < 4; ++k) X = X + weights[k] * node(el[std::size_t(sub[k])]);
        return std::make_pair(std::size_t(e), X);
      }
    }
    return std::nullopt;
  }

  std::optional<Inverse> invert(const Vec3& x) const;
};

std::optional<FiniteElementDisplacement::Inverse> FiniteElementDisplacement::Impl::invert(const Vec3& x) const
{
  const auto guess = deformedGuess(x);
  if (!guess) return std::nullopt;
  constexpr double tolerance = 1e-6; // mm
  Inverse result;
  // Fixed point X <- x' - u(X): contracts where |grad u| < 1, which holds for a smooth subsidence.
  Vec3 X = guess->second;
  std::optional<std::size_t> element = guess->first;
  for (int iteration = 0; iteration < 100; ++iteration) {
    element = locate(X, element);
    const Vec3 next = x - displacement(*element, X);
    const double step = norm(next - X);
    X = next;
    if (step < tolerance) {
      result.preoperative = X;
      return result;
    }
  }
  // Newton on X + u(X) = x' from the guess, where the fixed point stalls (steep gradients near the cap's rim).
  result.newton = true;
  X = guess->second;
  element = guess->first;
  for (int iteration = 0; iteration < 50; ++iteration) {
    element = locate(X, element);
    Mat3 G;
    const Vec3 residual = X + displacement(*element, X, &G) - x;
    if (norm(residual) < tolerance) {
      result.preoperative = X;
      return result;
    }
    for (int d = 0; d < 3; ++d) G[std::size_t(d)][std::size_t(d)] += 1;
    const auto inverse = inverseOfColumns({G[0][0], G[1][0], G[2][0]}, {G[0][1], G[1][1], G[2][1]}, {G[0][2], G[1][2], G[2][2]});
    if (!inverse) break;
    X = X - times(*inverse, residual);
  }
  result.converged = false;
  result.preoperative = X;
  return result;
}

FiniteElementDisplacement::FiniteElementDisplacement(const FiniteElementTruthModel& model) : impl(std::make_unique<Impl>(model)) {}
FiniteElementDisplacement::~FiniteElementDisplacement() = default;

std::optional<std::array<double, 3>> FiniteElementDisplacement::at(const std::array<double, 3>& X) const
{
  const auto element = impl->locate(X);
  if (!element) return std::nullopt;
  return impl->displacement(*element, X);
}

std::optional<FiniteElementDisplacement::Inverse> FiniteElementDisplacement::preoperativePosition(const std::array<double, 3>& x) const
{
  return impl->invert(x);
}

// ---- The resampling field ----------------------------------------------------------------------

namespace {
/// The deformed surface as straight triangles (4 per quadratic face) for nearest-point queries.
vtkSmartPointer<vtkPolyData> deformedSurface(const FiniteElementTruthModel& model)
{
  vtkNew<vtkPoints> points;
  points->SetDataTypeToDouble();
  points->SetNumberOfPoints(vtkIdType(model.nodes.size()));
  for (std::size_t v = 0; v < model.nodes.size(); ++v) {
    const Vec3 q = model.nodes[v] + model.displacements[v];
    points->SetPoint(vtkIdType(v), q.data());
  }
  vtkNew<vtkCellArray> triangles;
  for (const auto& f : model.boundaryFaces) { // a b c, ab bc ca
    const vtkIdType pieces[4][3] = {{f[0], f[3], f[5]}, {f[3], f[1], f[4]}, {f[5], f[4], f[2]}, {f[3], f[4], f[5]}};
    for (const auto& t : pieces) triangles->InsertNextCell(3, t);
  }
  auto surface = vtkSmartPointer<vtkPolyData>::New();
  surface->SetPoints(points);
  surface->SetPolys(triangles);
  return surface;
}

/// w at the point `b` of the deformed triangle `cell`: minus u interpolated linearly on it.
Vec3 surfaceResampling(const FiniteElementTruthModel& model, vtkPolyData* surface, vtkIdType cell, const Vec3& b)
{
  const vtkIdType* ids = nullptr;
  vtkIdType count = 0;
  surface->GetCellPoints(cell, count, ids);
  Vec3 q[3];
  for (int k = 0; k < 3; ++k) q[k] = model.nodes[std::size_t(ids[k])] + model.displacements[std::size_t(ids[k])];
  const Vec3 e1 = q[1] - q[0], e2 = q[2] - q[0], r = b - q[0];
  const double a11 = dot(e1, e1), a12 = dot(e1, e2), a22 = dot(e2, e2), det = a11 * a22 - a12 * a12;
  double l1 = 0, l2 = 0;
  if (det > 1e-18) {
    l1 = std::clamp((a22 * dot(r, e1) - a12 * dot(r, e2)) / det, 0.0, 1.0);
    l2 = std::clamp((a11 * dot(r, e2) - a12 * dot(r, e1)) / det, 0.0, 1.0 - l1);
  }
  const double weights[3] = {1 - l1 - l2, l1, l2};
  Vec3 w{0, 0, 0};
  for (int k = 0; k < 3; ++k) w = w - weights[k] * model.displacements[std::size_t(ids[k])];
  return w;
}
} // namespace

void fillFiniteElementResamplingField(const FiniteElementTruthModel& model, itk::Image<itk::Vector<double, 3>, 3>& field,
                                      const FiniteElementTruthParameters& P, FiniteElementTruthFigures& figures)
{
  const auto start = std::chrono::steady_clock::now();
  const FiniteElementDisplacement inverse(model);
  const vtkSmartPointer<vtkPolyData> surface = deformedSurface(model);
  vtkNew<vtkStaticCellLocator> locator;
  locator->SetDataSet(surface);
  locator->BuildLocator();
  vtkNew<vtkGenericCell> scratch;
  // Outside the deformed brain: w of the nearest surface point, kept up to the largest surface displacement
  // (+1 mm) so that the whole gap maps outside the preoperative brain, then faded out with a half cosine.
  double keep = 0;
  for (const auto& f : model.boundaryFaces) {
    for (std::int64_t v : f) keep = std::max(keep, norm(model.displacements[std::size_t(v)]));
  }
  keep += 1.0;
  const double reach = keep + P.fieldTaperMm;
  figures.newtonFallbacks = figures.unconvergedInversions = 0;
  itk::ImageRegionIteratorWithIndex<itk::Image<itk::Vector<double, 3>, 3>> it(&field, field.GetLargestPossibleRegion());
  for (; !it.IsAtEnd(); ++it) {
    itk::Point<double, 3> point;
    field.TransformIndexToPhysicalPoint(it.GetIndex(), point);
    const Vec3 x{point[0], point[1], point[2]};
    Vec3 w{0, 0, 0};
    if (const auto inside = inverse.preoperativePosition(x)) {
      w = inside->preoperative - x;
      figures.newtonFallbacks += inside->newton;
      figures.unconvergedInversions += !inside->converged;
    } else {
      double closest[3], distance2 = 0;
      vtkIdType cell = -1;
      int subId = 0;
      Vec3 query = x;
      if (locator->FindClosestPointWithinRadius(query.data(), reach, closest, scratch, cell, subId, distance2) && cell >= 0) {
        const double d = std::sqrt(distance2);
        const double fade = d <= keep ? 1.0 : 0.5 * (1 + std::cos(M_PI * (d - keep) / P.fieldTaperMm));
        w = fade * surfaceResampling(model, surface, cell, {closest[0], closest[1], closest[2]});
      }
    }
    it.Set(itk::Vector<double, 3>(w.data()));
  }
  figures.fieldSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

FiniteElementTruthFigures solveFiniteElementTruth(const LabelImage& preopLabels, itk::Image<itk::Vector<double, 3>, 3>& resamplingField,
                                                  const FiniteElementTruthParameters& parameters)
{
  FiniteElementTruthFigures figures;
  FiniteElementTruthModel model = buildFiniteElementTruthModel(preopLabels, parameters, &figures);
  solveFiniteElementTruthModel(model, parameters, figures);
  fillFiniteElementResamplingField(model, resamplingField, parameters, figures);
  return figures;
}

} // namespace brainshift
