#include "ActiveSurfaceLogic.h"

#include "Configuration.h"

#include "DistanceMaps.h"
#include "LabelMapMesher.h"

#include <itkRegionOfInterestImageFilter.h>
#include <itkSmoothingRecursiveGaussianImageFilter.h>

// ITK brings its own Eigen; a second copy in the same translation unit clashes.
#include <itk_eigen.h>
#include ITK_EIGEN(Dense)
#include ITK_EIGEN(Sparse)
#include ITK_EIGEN(SparseCholesky)

#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkDoubleArray.h>
#include <vtkIdList.h>
#include <vtkIntArray.h>
#include <vtkPointData.h>
#include <vtkPoints.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <limits>
#include <memory>
#include <mutex>
#include <map>
#include <optional>
#include <set>
#include <tuple>
#include <sstream>

namespace brainshift {

namespace {
using Vec = Eigen::Vector3d;

/// The distance maps cover the surface's box and this much around it: more than the brain can
/// shift for the intraoperative target; a lattice step and the smoothing for the preoperative one.
constexpr double CropMarginMm = 25.0, PreopCropMarginMm = 10.0;

double secondsSince(std::chrono::steady_clock::time_point start)
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// Preoperative (model frame) point -> continuous index of the intraoperative grid: the inverse
/// of the rigid intraop -> preop transform, then the grid's physical -> index map.
struct PreopToIntraopIndex {
  Eigen::Matrix3d matrix;
  Vec offset;
  Vec operator()(const Vec& x) const { return matrix * x + offset; }
  /// A gradient taken in index space, brought to the model frame.
  Vec gradientToPreop(const Vec& indexGradient) const { return matrix.transpose() * indexGradient; }
};

PreopToIntraopIndex preopToIntraopIndex(const SpatialTransform& rigid, const ImageGeometry& grid)
{
  const AffineParameters a = affineParametersOf(&rigid);
  Eigen::Matrix3d A, D = Eigen::Matrix3d::Zero(), S = Eigen::Matrix3d::Zero();
  Vec t, o;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      A(i, j) = a.matrix[i][j];
      D(i, j) = grid.direction[unsigned(i)][unsigned(j)];
    }
    t[i] = a.translation[i];
    o[i] = grid.origin[unsigned(i)];
    S(i, i) = grid.spacing[unsigned(i)];
  }
  const Eigen::Matrix3d physicalToIndex = (D * S).inverse();
  const Eigen::Matrix3d preopToIntraop = A.inverse();
  PreopToIntraopIndex map;
  map.matrix = physicalToIndex * preopToIntraop;
  map.offset = physicalToIndex * (-preopToIntraop * t - o);
  return map;
}

/// Trilinear samples (and index-space gradients) of a float volume.
class TrilinearVolume {
public:
  explicit TrilinearVolume(const ScalarImage& image)
    : data_(image.GetBufferPointer())
  {
    const auto size = image.GetLargestPossibleRegion().GetSize();
    for (int d = 0; d < 3; ++d) size_[d] = long(size[unsigned(d)]);
  }

  static bool insideGrid(const Vec& index, const ImageGeometry& grid)
  {
    for (unsigned d = 0; d < 3; ++d) {
      if (!(index[int(d)] >= -0.5 && index[int(d)] <= double(grid.size[d]) - 0.5)) return false;
    }
    return true;
  }

  /// Within half a voxel of the grid.
  bool inside(const Vec& index) const
  {
    for (int d = 0; d < 3; ++d) {
      if (!(index[d] >= -0.5 && index[d] <= double(size_[d]) - 0.5)) return false;
    }
    return true;
  }

  double value(const Vec& index, Vec* gradient = nullptr) const
  {
    long i0[3];
    double f[3];
    for (int d = 0; d < 3; ++d) {
      const double c = std::clamp(index[d], 0.0, double(size_[d] - 1));
      i0[d] = std::min(long(std::floor(c)), std::max(size_[d] - 2, 0L));
      f[d] = size_[d] > 1 ? c - double(i0[d]) : 0.0;
    }
    auto at = [&](int dx, int dy, int dz) {
      const long x = std::min(i0[0] + dx, size_[0] - 1), y = std::min(i0[1] + dy, size_[1] - 1), z = std::min(i0[2] + dz, size_[2] - 1);
      return double(data_[x + size_[0] * (y + size_[1] * z)]);
    };
    const double c000 = at(0, 0, 0), c100 = at(1, 0, 0), c010 = at(0, 1, 0), c110 = at(1, 1, 0);
    const double c001 = at(0, 0, 1), c101 = at(1, 0, 1), c011 = at(0, 1, 1), c111 = at(1, 1, 1);
    const double c00 = c000 + f[0] * (c100 - c000), c10 = c010 + f[0] * (c110 - c010);
    const double c01 = c001 + f[0] * (c101 - c001), c11 = c011 + f[0] * (c111 - c011);
    const double c0 = c00 + f[1] * (c10 - c00), c1 = c01 + f[1] * (c11 - c01);
    if (gradient) {
      const double gx0 = (1 - f[1]) * (c100 - c000) + f[1] * (c110 - c010);
      const double gx1 = (1 - f[1]) * (c101 - c001) + f[1] * (c111 - c011);
      (*gradient)[0] = (1 - f[2]) * gx0 + f[2] * gx1;
      (*gradient)[1] = (1 - f[2]) * (c10 - c00) + f[2] * (c11 - c01);
      (*gradient)[2] = c1 - c0;
    }
    return c0 + f[2] * (c1 - c0);
  }

private:
  const float* data_;
  long size_[3];
};

/// A label map's voxel grid: its 6-neighbours of a voxel (by linear index).
struct VoxelGrid {
  long nx, ny, nz;

  template <class Visit>
  void forEachNeighbour(std::size_t i, Visit&& visit) const
  {
    const long x = long(i % std::size_t(nx)), y = long((i / std::size_t(nx)) % std::size_t(ny)), z = long(i / std::size_t(nx * ny));
    if (x > 0) visit(i - 1);
    if (x + 1 < nx) visit(i + 1);
    if (y > 0) visit(i - std::size_t(nx));
    if (y + 1 < ny) visit(i + std::size_t(nx));
    if (z > 0) visit(i - std::size_t(nx * ny));
    if (z + 1 < nz) visit(i + std::size_t(nx * ny));
  }
  bool onBorder(std::size_t i) const
  {
    const long x = long(i % std::size_t(nx)), y = long((i / std::size_t(nx)) % std::size_t(ny)), z = long(i / std::size_t(nx * ny));
    return x == 0 || y == 0 || z == 0 || x == nx - 1 || y == ny - 1 || z == nz - 1;
  }
};

/// The 6-connected components of the brain voxels, numbered from 1 in voxel order (deterministic;
/// 0: not brain), with their sizes (componentSize[0] unused).
struct BrainComponents {
  std::vector<int> component;
  std::vector<std::size_t> componentSize{0};
  int largest = 0;
};

BrainComponents brainComponentsOf(const std::vector<unsigned char>& inBrain, const VoxelGrid& grid)
{
  const std::size_t n = inBrain.size();
  BrainComponents components;
  components.component.assign(n, 0);
  std::vector<std::size_t> queue;
  for (std::size_t seed = 0; seed < n; ++seed) {
    if (!inBrain[seed] || components.component[seed]) continue;
    const int id = int(components.componentSize.size());
    components.componentSize.push_back(0);
    queue.assign(1, seed);
    components.component[seed] = id;
    while (!queue.empty()) {
      const std::size_t i = queue.back();
      queue.pop_back();
      ++components.componentSize[std::size_t(id)];
      grid.forEachNeighbour(i, [&](std::size_t j) {
        if (inBrain[j] && !components.component[j]) {
          components.component[j] = id;
          queue.push_back(j);
        }
      });
    }
  }
  const auto& sizes = components.componentSize;
  components.largest = int(std::max_element(sizes.begin(), sizes.end()) - sizes.begin());
  return components;
}

/// Refuses (InputError) a brain in two large pieces (the next holds more than a fifth); warns
/// when more than 1 % lies apart from the largest piece.
void requireOneBrain(const BrainComponents& components, std::size_t brainVoxels, const std::string& labelsName, Warnings& warnings)
{
  const double keptFraction = double(components.componentSize[std::size_t(components.largest)]) / double(brainVoxels);
  std::size_t secondLargest = 0;
  for (std::size_t c = 1; c < components.componentSize.size(); ++c) {
    if (int(c) != components.largest) secondLargest = std::max(secondLargest, components.componentSize[c]);
  }
  if (double(secondLargest) > 0.2 * double(brainVoxels)) {
    std::ostringstream m;
    m << labelsName << ": the intraoperative brain is disjoint (its largest connected part holds "
      << int(std::lround(100 * keptFraction)) << " % of it, the next " << int(std::lround(100.0 * double(secondLargest) / double(brainVoxels)))
      << " %); no single brain surface to match";
    throw InputError(m.str());
  }
  if (keptFraction < 0.99) {
    std::ostringstream w;
    w << "surface: " << int(std::lround(100 * (1 - keptFraction)))
      << " % of the intraoperative brain is in pieces apart from the brain; they are ignored";
    warnings.push_back(w.str());
  }
}

/// What the outside reaches from the grid's border without crossing the largest brain component:
/// everything else (the brain, the cavity, enclosed holes) is the filled brain.
std::vector<unsigned char> reachableFromOutside(const BrainComponents& components, const VoxelGrid& grid)
{
  const std::size_t n = components.component.size();
  const int largest = components.largest;
  std::vector<unsigned char> outside(n, 0);
  std::vector<std::size_t> queue;
  for (std::size_t i = 0; i < n; ++i) {
    if (grid.onBorder(i) && components.component[i] != largest) {
      outside[i] = 1;
      queue.push_back(i);
    }
  }
  while (!queue.empty()) {
    const std::size_t i = queue.back();
    queue.pop_back();
    grid.forEachNeighbour(i, [&](std::size_t j) {
      if (!outside[j] && components.component[j] != largest) {
        outside[j] = 1;
        queue.push_back(j);
      }
    });
  }
  return outside;
}

/// The target: the intraoperative brain as one solid (the largest 6-connected component of the
/// brain labels, its enclosed holes such as a resection cavity filled).
MaskImage::Pointer targetBrainMask(const LabelImage& labels, const std::set<int>& brain, const std::string& labelsName,
                                   Warnings& warnings)
{
  const auto size = labels.GetLargestPossibleRegion().GetSize();
  const VoxelGrid grid{long(size[0]), long(size[1]), long(size[2])};
  const std::size_t n = labels.GetLargestPossibleRegion().GetNumberOfPixels();
  const LabelPixel* l = labels.GetBufferPointer();
  std::vector<unsigned char> inBrain(n, 0);
  std::size_t brainVoxels = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (brain.count(l[i])) {
      inBrain[i] = 1;
      ++brainVoxels;
    }
  }
  if (brainVoxels == 0) throw InputError(labelsName + ": the intraoperative segmentation holds no brain (labels 2-4)");
  const BrainComponents components = brainComponentsOf(inBrain, grid);
  requireOneBrain(components, brainVoxels, labelsName, warnings);
  const std::vector<unsigned char> outside = reachableFromOutside(components, grid);
  auto mask = MaskImage::New();
  mask->SetRegions(labels.GetLargestPossibleRegion());
  mask->CopyInformation(&labels);
  mask->Allocate();
  unsigned char* m = mask->GetBufferPointer();
  for (std::size_t i = 0; i < n; ++i) m[i] = outside[i] ? 0 : 1;
  return mask;
}

ScalarImage::Pointer smoothed(const ScalarImage::Pointer& image, double sigmaMm)
{
  if (sigmaMm <= 0) return image;
  using Smoother = itk::SmoothingRecursiveGaussianImageFilter<ScalarImage, ScalarImage>;
  auto smoother = Smoother::New();
  smoother->SetInput(image);
  Smoother::SigmaArrayType sigma;
  // The recursive filter needs about half a voxel of sigma to stay accurate.
  for (unsigned d = 0; d < 3; ++d) sigma[d] = std::max(sigmaMm, 0.5 * image->GetSpacing()[d]);
  smoother->SetSigmaArray(sigma);
  smoother->Update();
  ScalarImage::Pointer out = smoother->GetOutput();
  out->DisconnectPipeline();
  return out;
}

double median(std::vector<double> values)
{
  if (values.empty()) return 0;
  auto middle = values.begin() + std::ptrdiff_t(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

double percentile(std::vector<double> values, double p)
{
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  const double rank = p * double(values.size() - 1);
  const std::size_t below = std::size_t(std::floor(rank));
  const std::size_t above = std::min(values.size() - 1, below + 1);
  return values[below] + (rank - double(below)) * (values[above] - values[below]);
}

struct SurfaceTopology {
  std::vector<std::array<vtkIdType, 3>> triangles;
  std::vector<std::pair<int, int>> edges;
};

SurfaceTopology topologyOf(vtkPolyData* surface, const std::string& meshName)
{
  SurfaceTopology topology;
  std::map<std::pair<vtkIdType, vtkIdType>, int> edgeUse;
  vtkCellArray* polys = surface->GetPolys();
  vtkNew<vtkIdList> ids;
  for (polys->InitTraversal(); polys->GetNextCell(ids);) {
    std::array<vtkIdType, 3> t{ids->GetId(0), ids->GetId(1), ids->GetId(2)};
    topology.triangles.push_back(t);
    for (int e = 0; e < 3; ++e) edgeUse[{std::min(t[std::size_t(e)], t[std::size_t((e + 1) % 3)]), std::max(t[std::size_t(e)], t[std::size_t((e + 1) % 3)])}] += 1;
  }
  std::size_t bad = 0;
  for (const auto& [edge, uses] : edgeUse) {
    if (uses != 2) ++bad;
    topology.edges.emplace_back(int(edge.first), int(edge.second));
  }
  if (bad > 0) {
    throw InputError(meshName + ": the brain surface of the mesh is not a closed manifold (" + std::to_string(bad) +
                     " edges not shared by exactly two triangles)");
  }
  return topology;
}

/// Taubin's lambda|mu smoothing (lambda 0.5, mu -0.53) with the umbrella operator of `laplacian`.
Eigen::MatrixXd taubinSmoothed(Eigen::MatrixXd positions, const Eigen::SparseMatrix<double>& laplacian, unsigned iterations)
{
  const Eigen::VectorXd degree = laplacian.diagonal();
  for (unsigned k = 0; k < iterations; ++k) {
    for (double factor : {0.5, -0.53}) {
      // umbrella(x)_i = mean of the neighbours - x_i = -(K x)_i / degree_i
      const Eigen::MatrixXd umbrella = -(degree.cwiseInverse().asDiagonal() * (laplacian * positions));
      positions += factor * umbrella;
    }
  }
  return positions;
}

Vec triangleNormal(const std::vector<Vec>& x, const std::array<vtkIdType, 3>& t)
{
  return (x[std::size_t(t[1])] - x[std::size_t(t[0])]).cross(x[std::size_t(t[2])] - x[std::size_t(t[0])]);
}


/// The voxels of `grid` within `marginMm` of the points (given as continuous indices), clamped to it.
itk::ImageRegion<3> regionAround(const ImageGeometry& grid, const std::vector<Vec>& indices, double marginMm)
{
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (const Vec& c : indices) {
    for (int d = 0; d < 3; ++d) {
      lo[d] = std::min(lo[d], c[d]);
      hi[d] = std::max(hi[d], c[d]);
    }
  }
  itk::ImageRegion<3> region;
  for (unsigned d = 0; d < 3; ++d) {
    const double margin = marginMm / grid.spacing[d];
    const long first = std::clamp(long(std::floor(lo[d] - margin)), 0L, long(grid.size[d]) - 1);
    const long last = std::clamp(long(std::ceil(hi[d] + margin)), first, long(grid.size[d]) - 1);
    region.SetIndex(d, first);
    region.SetSize(d, std::size_t(last - first + 1));
  }
  return region;
}

template <class TImage>
typename TImage::Pointer cropped(const TImage& image, const itk::ImageRegion<3>& region)
{
  auto crop = itk::RegionOfInterestImageFilter<TImage, TImage>::New();
  crop->SetInput(&image);
  crop->SetRegionOfInterest(region);
  crop->Update();
  typename TImage::Pointer out = crop->GetOutput();
  out->DisconnectPipeline();
  return out;
}

/// Free reasons of the surface nodes (0: imposed, matched to the target).
enum FreeReason : unsigned char {
  Matched = 0,
  ResectedTumour = 1,
  OutsideImage = 2,     ///< outside the field of view, left to the elastic model
  Unmatched = 3,
  HeldOutsideImage = 4  ///< outside the field of view, held at rest (imposed, zero displacement)
};

/// The meshed brain's volume (ml) whose tetrahedra have their centroid inside the intraoperative
/// grid (through `toIndex`), and the whole (`totalMl`).
double coveredBrainVolumeMl(vtkUnstructuredGrid* mesh, vtkDataArray* cellLabels, const std::set<int>& brain,
                            const PreopToIntraopIndex& toIndex, const ImageGeometry& grid, double& totalMl)
{
  double covered = 0;
  totalMl = 0;
  vtkNew<vtkIdList> ids;
  for (vtkIdType c = 0; c < mesh->GetNumberOfCells(); ++c) {
    if (!brain.count(int(std::lround(cellLabels->GetComponent(c, 0))))) continue;
    mesh->GetCellPoints(c, ids);
    Vec q[4];
    for (int v = 0; v < 4; ++v) mesh->GetPoint(ids->GetId(v), q[v].data());
    const double volumeMl = std::abs((q[1] - q[0]).dot((q[2] - q[0]).cross(q[3] - q[0]))) / 6000.0;
    totalMl += volumeMl;
    if (TrilinearVolume::insideGrid(toIndex(0.25 * (q[0] + q[1] + q[2] + q[3])), grid)) covered += volumeMl;
  }
  return covered;
}

/// Refuses (InputError) a field of view that covers too little of the brain to say anything,
/// naming both figures.
void requireEnoughCoverage(const ActiveSurfaceResult& r, const ActiveSurfaceParameters& p, const std::string& labelsName)
{
  const double share = r.surfaceNodes ? double(r.coveredSurfaceNodes) / double(r.surfaceNodes) : 0.0;
  if (share >= p.minimumCoveredSurfaceShare && r.coveredBrainMl >= p.minimumCoveredBrainMl) return;
  std::ostringstream m;
  m << labelsName << ": the intraoperative image covers too little of the brain to match its surface: "
    << int(std::lround(100 * share)) << " % of the brain surface nodes (" << r.coveredSurfaceNodes << " of " << r.surfaceNodes
    << ") and " << std::lround(r.coveredBrainMl) << " ml of the " << std::lround(r.meshedBrainMl)
    << " ml brain lie inside its field of view after the rigid transform (at least "
    << int(std::lround(100 * p.minimumCoveredSurfaceShare)) << " % and " << std::lround(p.minimumCoveredBrainMl) << " ml are needed)";
  throw InputError(m.str());
}

double mean(const std::vector<double>& values)
{
  double sum = 0;
  for (double v : values) sum += v;
  return values.empty() ? 0 : sum / double(values.size());
}

/// A physical point of an image's own frame -> its continuous index.
PreopToIntraopIndex physicalToIndexOf(const ImageGeometry& grid)
{
  Eigen::Matrix3d D, S = Eigen::Matrix3d::Zero();
  Vec o;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) D(i, j) = grid.direction[unsigned(i)][unsigned(j)];
    S(i, i) = grid.spacing[unsigned(i)];
    o[i] = grid.origin[unsigned(i)];
  }
  PreopToIntraopIndex map;
  map.matrix = (D * S).inverse();
  map.offset = -map.matrix * o;
  return map;
}


/// The implicit elastic step: solves (I + tau (alpha K + beta K^2)) v = b. When the polynomial has
/// real roots it is factorised as (I + a K)(I + c K), two sparse systems with the Laplacian's own
/// sparsity (K^2 alone fills in several times more, and the solve is the stage's inner loop).
class MembraneStep {
public:
  MembraneStep(const Eigen::SparseMatrix<double>& laplacian, const ActiveSurfaceParameters& p)
  {
    using SparseMatrix = Eigen::SparseMatrix<double>;
    SparseMatrix identity(laplacian.rows(), laplacian.cols());
    identity.setIdentity();
    const double sum = p.timeStep * p.membraneWeight, product = p.timeStep * p.bendingWeight;
    const double discriminant = sum * sum - 4 * product;
    if (discriminant >= 0) {
      const double a = 0.5 * (sum + std::sqrt(discriminant)), c = 0.5 * (sum - std::sqrt(discriminant));
      first_.compute(identity + a * laplacian);
      second_.compute(identity + c * laplacian);
      factored_ = true;
      ok_ = first_.info() == Eigen::Success && second_.info() == Eigen::Success;
    } else {
      first_.compute(identity + sum * laplacian + product * SparseMatrix(laplacian * laplacian));
      ok_ = first_.info() == Eigen::Success;
    }
  }
  bool ok() const { return ok_; }
  Eigen::MatrixXd solve(const Eigen::MatrixXd& b) const
  {
    Eigen::MatrixXd x = first_.solve(b);
    return factored_ ? Eigen::MatrixXd(second_.solve(x)) : x;
  }

private:
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> first_, second_;
  bool factored_ = false, ok_ = false;
};

/// The membrane's low-pass filter F = (I + alpha K + beta K^2)^-1: the iterations' own step when
/// their tau is 1 (the default), else one factorised with tau = 1. The residual correction and the
/// rest band filter with it.
class MembraneFilter {
public:
  MembraneFilter(const Eigen::SparseMatrix<double>& laplacian, const MembraneStep& iterationStep, const ActiveSurfaceParameters& p)
    : iterationStep_(iterationStep)
  {
    if (p.timeStep == 1.0) return;
    ActiveSurfaceParameters unit = p;
    unit.timeStep = 1.0;
    own_.emplace(laplacian, unit);
  }
  const MembraneStep& step() const { return own_ ? *own_ : iterationStep_; }

private:
  const MembraneStep& iterationStep_;
  std::optional<MembraneStep> own_;
};

/// One way the brain's surroundings differ from it in this scan: darker (insideSign +1: CSF and
/// bone in T1, air and bone in every contrast) or brighter (-1: CSF and fluid in T2).
struct OutsideSide {
  double threshold = 0, insideSign = 1;
  double contrast = 0; ///< |expected inside - expected outside|
};

/// The image term: where, along a line, the intensity passes from the expected inside grey level
/// to an expected outside one. One side where the surroundings are on one side of the brain (T1,
/// FLAIR: dark fluid, bone and air); two where they lie on both (T2: bright fluid, dark bone and air).
struct ImageEdgeTerm {
  ScalarImage::Pointer keepAlive;
  std::unique_ptr<TrilinearVolume> intensity;
  std::vector<OutsideSide> sides;
};

/// The expected grey levels: `inside` and `outside` from the segmentation's boundary band. The
/// surroundings are two-sided when at least `minimumShare` of the outside band lies on each side of
/// the inside median; each side's level is then the median of its part.
std::vector<OutsideSide> outsideSides(const std::vector<double>& inside, const std::vector<double>& outside,
                                      double minimumShare, double& brighterShare)
{
  const double in = median(inside), out = median(outside);
  std::vector<double> darker, brighter;
  for (double v : outside) (v > in ? brighter : darker).push_back(v);
  brighterShare = outside.empty() ? 0.0 : double(brighter.size()) / double(outside.size());
  auto sideTowards = [&](double level) {
    return OutsideSide{0.5 * (in + level), in >= level ? 1.0 : -1.0, std::abs(in - level)};
  };
  if (std::min(brighterShare, 1.0 - brighterShare) < minimumShare) return {sideTowards(out)};
  return {sideTowards(median(darker)), sideTowards(median(brighter))};
}

struct FitOutcome {
  Eigen::MatrixXd positions;
  std::vector<double> residuals; ///< |distance to the target boundary| at the end
  std::vector<bool> imageUsed;
  /// Whether the segmentation's boundary showed the expected contrast at the node (1), not (0), or
  /// was not checked (-1: no image term).
  std::vector<signed char> plausible;
  /// The pull on each node at the end (mm, towards its target): at the membrane's equilibrium, what
  /// it leaves between the node and its target.
  Eigen::MatrixXd pull;
  unsigned iterations = 0;
  bool converged = false;
};

std::vector<double> residualsAt(const Eigen::MatrixXd& positions, const TrilinearVolume& field, const PreopToIntraopIndex& toIndex)
{
  std::vector<double> r(std::size_t(positions.rows()));
  for (Eigen::Index i = 0; i < positions.rows(); ++i) r[std::size_t(i)] = std::abs(field.value(toIndex(positions.row(i).transpose())));
  return r;
}

/// Moves `rest` onto the zero level of `field` (reached through `toIndex`): semi-implicit steps of
/// the membrane on v = x - rest. Nodes with a non-zero `freeReason` feel no external force.
/// Targets on the boundary for some nodes (the sinking direction's matches): such a node is pulled
/// towards its point instead of along the distance map's gradient.
struct PointTargets {
  std::vector<bool> used;
  std::vector<Vec> points;
};

/// Whether the segmentation's boundary at a node shows the expected contrast: across it the mean
/// intensity 1-4 mm inside and 1-4 mm outside must differ as brain and its surroundings do (a local
/// test, so a bias field does not upset it), towards one of the sides. Where the surroundings lie on
/// both sides (T2: bright fluid 1 mm out, dark bone 3 mm out, whose mean may equal the brain's),
/// also when most samples outside are beyond a side's threshold and most inside are not.
bool showsExpectedContrast(const ImageEdgeTerm& edges, const Vec& index, const Vec& indexStep, double target, double step,
                           const ActiveSurfaceParameters& p)
{
  double inside = 0, outside = 0;
  int count = 0, outsideLike = 0, insideLike = 0;
  auto beyond = [&](double v) {
    for (const OutsideSide& side : edges.sides) {
      if (side.insideSign * (v - side.threshold) <= 0) return true;
    }
    return false;
  };
  for (double at = 1.0; at <= 4.0; at += step, ++count) {
    const double in = edges.intensity->value(index + ((target - at) / step) * indexStep);
    const double out = edges.intensity->value(index + ((target + at) / step) * indexStep);
    inside += in;
    outside += out;
    insideLike += !beyond(in);
    outsideLike += beyond(out);
  }
  for (const OutsideSide& side : edges.sides) {
    if (side.insideSign * (inside - outside) / double(count) > p.minimumContrastFraction * side.contrast) return true;
  }
  return edges.sides.size() > 1 && 2 * outsideLike > count && 2 * insideLike > count;
}

/// The crossing from inside-like to outside-like (towards `side`) nearest to the node, within
/// `searchMm` along the normal, if nearer than `edgeDistance` (then `edgeAt` and `edgeDistance` are set).
void nearestEdge(const ImageEdgeTerm& edges, const OutsideSide& side, const Vec& index, const Vec& indexStep, double step,
                 double searchMm, double& edgeAt, double& edgeDistance)
{
  const int samples = int(std::lround(searchMm / step));
  double previous = side.insideSign * (edges.intensity->value(index - double(samples) * indexStep) - side.threshold);
  for (int k = -samples + 1; k <= samples; ++k) {
    const double g = side.insideSign * (edges.intensity->value(index + double(k) * indexStep) - side.threshold);
    if (previous > 0 && g <= 0) {
      const double at = step * (double(k - 1) + previous / (previous - g));
      if (std::abs(at) < edgeDistance) {
        edgeDistance = std::abs(at);
        edgeAt = at;
      }
    }
    previous = g;
  }
}

/// The active surface's iterations (see fitSurface): the state shared by its steps.
class SurfaceFit {
public:
  SurfaceFit(const MembraneStep& membrane, const Eigen::MatrixXd& rest, const TrilinearVolume& field, const PreopToIntraopIndex& toIndex,
             const ImageEdgeTerm* edges, const std::vector<unsigned char>& freeReason, const ActiveSurfaceParameters& p,
             const PointTargets* targets)
    : membrane_(membrane), rest_(rest), field_(field), toIndex_(toIndex), edges_(edges), freeReason_(freeReason), p_(p),
      targets_(targets), n_(rest.rows()), force_(n_, 3), plausible_(std::size_t(n_), -1)
  {
    out_.residuals.assign(std::size_t(n_), 0.0);
    out_.imageUsed.assign(std::size_t(n_), false);
  }

  FitOutcome run(const Eigen::MatrixXd* start);

private:
  Vec pull(Eigen::Index node, const Vec& x, double& residual, bool& imageUsed);
  double imageTarget(Eigen::Index node, const Vec& index, const Vec& direction, double target, double& residual, bool& imageUsed);
  void computeForces();
  bool settled(const Eigen::VectorXd& moves, std::vector<double>& recentMean) const;

  const MembraneStep& membrane_;
  const Eigen::MatrixXd& rest_;
  const TrilinearVolume& field_;
  const PreopToIntraopIndex& toIndex_;
  const ImageEdgeTerm* edges_;
  const std::vector<unsigned char>& freeReason_;
  const ActiveSurfaceParameters& p_;
  const PointTargets* targets_;
  const Eigen::Index n_;
  FitOutcome out_;
  Eigen::MatrixXd v_, force_;
  // Whether the segmentation looks right at a node is decided every few iterations, not at every
  // step: a node on the fence between the two would otherwise dither and never settle.
  std::vector<signed char> plausible_;
  bool refreshPlausibility_ = true;
};

/// The pull on a node at x: along the distance map's gradient (outward), to the target boundary
/// (the segmentation's, or the image's edge where the image term decides), at most the largest step.
Vec SurfaceFit::pull(Eigen::Index node, const Vec& x, double& residual, bool& imageUsed)
{
  imageUsed = false;
  const Vec index = toIndex_(x);
  Vec gradient;
  const double d = field_.value(index, &gradient);
  residual = std::abs(d);
  Vec direction = toIndex_.gradientToPreop(gradient);
  const double length = direction.norm();
  if (!(length > 1e-6)) return Vec::Zero();
  direction /= length;
  double target = -d; // along `direction` (outward): the segmentation's boundary
  if (edges_) target = imageTarget(node, index, direction, target, residual, imageUsed);
  return std::clamp(target, -p_.maximumStepMm, p_.maximumStepMm) * direction;
}

/// The image term's say on the target along the normal. The expected contrast checks the
/// segmentation: across its boundary the mean intensity of a few mm inside and of a few mm outside
/// must differ as brain and its surroundings do (a local test, so a bias field does not upset it).
/// Where it fails, the segmentation is wrong here (grown into fluid, or eroded into brain) and the
/// image alone decides.
double SurfaceFit::imageTarget(Eigen::Index node, const Vec& index, const Vec& direction, double target, double& residual,
                               bool& imageUsed)
{
  const double step = 0.5; // the crossing is interpolated within a step
  const Vec indexStep = toIndex_.matrix * direction * step;
  signed char& known = plausible_[std::size_t(node)];
  if (refreshPlausibility_ || known < 0) known = showsExpectedContrast(*edges_, index, indexStep, target, step, p_);
  const bool segmentationPlausible = known == 1;
  if (segmentationPlausible && !(p_.imageWeight > 0)) return target; // no edge needed
  // The image's edge nearest to the node: inside-like to outside-like along the normal.
  double edgeAt = 0, edgeDistance = std::numeric_limits<double>::infinity();
  for (const OutsideSide& side : edges_->sides) nearestEdge(*edges_, side, index, indexStep, step, p_.imageSearchMm, edgeAt, edgeDistance);
  const bool edgeFound = edgeDistance < std::numeric_limits<double>::infinity();
  if (segmentationPlausible) {
    if (p_.imageWeight > 0 && edgeFound && std::abs(edgeAt - target) <= p_.imageTrustMm) {
      target = (1 - p_.imageWeight) * target + p_.imageWeight * edgeAt;
      imageUsed = true;
    }
  } else if (!p_.imageRescue) {
    // the segmentation is followed anyway
  } else if (edgeFound) {
    target = edgeAt;
    residual = std::abs(edgeAt); // the node is matched to the image's edge
    imageUsed = true;
  } else {
    target = 0; // neither is to be trusted: the membrane carries the node
  }
  return target;
}

void SurfaceFit::computeForces()
{
  for (Eigen::Index i = 0; i < n_; ++i) {
    if (freeReason_[std::size_t(i)] == ResectedTumour || freeReason_[std::size_t(i)] == OutsideImage) {
      force_.row(i).setZero();
      continue;
    }
    if (freeReason_[std::size_t(i)] == HeldOutsideImage) { // back to rest: the skull holds it
      const double length = v_.row(i).norm();
      force_.row(i) = length > p_.maximumStepMm ? Eigen::RowVector3d(-v_.row(i) * (p_.maximumStepMm / length)) : Eigen::RowVector3d(-v_.row(i));
      continue;
    }
    bool image = false;
    const Vec x = rest_.row(i).transpose() + v_.row(i).transpose();
    Vec f = pull(i, x, out_.residuals[std::size_t(i)], image);
    if (targets_ && targets_->used[std::size_t(i)]) {
      const Vec towards = targets_->points[std::size_t(i)] - x;
      const double length = towards.norm();
      f = length > p_.maximumStepMm ? Vec(towards * (p_.maximumStepMm / length)) : towards;
      image = false;
    }
    out_.imageUsed[std::size_t(i)] = image;
    force_.row(i) = f.transpose();
  }
}

/// Converged when nearly every node has stopped (a few may dither on a voxel's edge: the 95th
/// percentile of the moves), or when the surface as a whole has stopped and only a few nodes dither
/// between an edge and the segmentation: the mean movement over the last five steps is below half
/// the threshold (after 30 iterations).
bool SurfaceFit::settled(const Eigen::VectorXd& moves, std::vector<double>& recentMean) const
{
  std::vector<double> sortedMoves(moves.data(), moves.data() + moves.size());
  auto at95 = sortedMoves.begin() + std::ptrdiff_t(0.95 * double(sortedMoves.size() - 1));
  std::nth_element(sortedMoves.begin(), at95, sortedMoves.end());
  const double movement = *at95;
  recentMean.push_back(moves.mean());
  bool quiet = false;
  if (recentMean.size() >= 5 && out_.iterations >= 30) {
    double sum = 0;
    for (std::size_t k = recentMean.size() - 5; k < recentMean.size(); ++k) sum += recentMean[k];
    quiet = sum / 5.0 < 0.5 * p_.convergenceMm;
  }
  return movement < p_.convergenceMm || quiet;
}

FitOutcome SurfaceFit::run(const Eigen::MatrixXd* start)
{
  v_ = start ? *start : Eigen::MatrixXd::Zero(n_, 3);
  computeForces();
  std::vector<double> recentMean;
  for (out_.iterations = 1; out_.iterations <= p_.maximumIterations; ++out_.iterations) {
    throwIfCancelled(p_.cancel, "the active surface");
    const Eigen::MatrixXd next = membrane_.solve(v_ + p_.timeStep * force_);
    const Eigen::VectorXd moves = (next - v_).rowwise().norm();
    v_ = next;
    refreshPlausibility_ = out_.iterations % 10 == 0;
    computeForces();
    refreshPlausibility_ = false;
    if (settled(moves, recentMean)) {
      out_.converged = true;
      break;
    }
  }
  out_.iterations = std::min(out_.iterations, p_.maximumIterations);
  out_.positions = rest_ + v_;
  out_.pull = force_;
  out_.plausible = edges_ ? plausible_ : std::vector<signed char>(std::size_t(n_), -1);
  return out_;
}

FitOutcome fitSurface(const MembraneStep& membrane, const Eigen::MatrixXd& rest,
                      const TrilinearVolume& field, const PreopToIntraopIndex& toIndex, const ImageEdgeTerm* edges,
                      const std::vector<unsigned char>& freeReason, const ActiveSurfaceParameters& p,
                      const Eigen::MatrixXd* start = nullptr, const PointTargets* targets = nullptr)
{
  return SurfaceFit(membrane, rest, field, toIndex, edges, freeReason, p, targets).run(start);
}
} // namespace

/// The brain under a craniotomy sinks as one body, in one direction; a closest-point match projects
/// that motion onto each node's normal and loses its tangential part (several mm on the flanks of a
/// 15 mm sink). The direction is estimated from the closest-point fit itself (the mean displacement
/// of the nodes that moved more than `sinkingNodeMm`: the tangential parts cancel over the bowl),
/// and each node that moved is matched again where the line from its preoperative place along that
/// direction meets the target boundary (the crossing nearest to where the closest-point fit put it).
/// Nodes whose normal is too oblique to the direction, that the image term placed, or whose line
/// meets no boundary near, keep the closest-point match.
struct SinkingDirectionMatch {
  Vec direction = Vec::Zero();
  PointTargets targets;
  std::size_t matched = 0;
};

SinkingDirectionMatch matchAlongSinkingDirection(const Eigen::MatrixXd& rest, const FitOutcome& closest,
                                                 const TrilinearVolume& field, const PreopToIntraopIndex& toIndex,
                                                 const std::vector<unsigned char>& freeReason, const ActiveSurfaceParameters& p)
{
  const std::size_t n = std::size_t(rest.rows());
  SinkingDirectionMatch match;
  match.targets.used.assign(n, false);
  match.targets.points.assign(n, Vec::Zero());
  Vec sum = Vec::Zero();
  double lengths = 0;
  std::size_t moving = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const Vec u = (closest.positions.row(Eigen::Index(i)) - rest.row(Eigen::Index(i))).transpose();
    if (freeReason[i] == 0 && u.norm() > p.sinkingNodeMm) {
      sum += u;
      lengths += u.norm();
      ++moving;
    }
  }
  // A common sinking: enough nodes moved, and their moves agree in direction (a swelling or a
  // uniform shrinking has none).
  if (moving < p.sinkingMinimumNodes || sum.norm() < p.sinkingCoherence * lengths) return match;
  match.direction = sum.normalized();
  const Vec& d = match.direction;
  const double step = 0.25;
  for (std::size_t i = 0; i < n; ++i) {
    if (freeReason[i] != 0 || closest.imageUsed[i]) continue;
    const Vec x = closest.positions.row(Eigen::Index(i)).transpose();
    const Vec from = rest.row(Eigen::Index(i)).transpose();
    if ((x - from).norm() <= p.directionalNodeMm) continue;
    Vec gradient;
    field.value(toIndex(x), &gradient);
    const Vec normal = toIndex.gradientToPreop(gradient);
    if (!(normal.norm() > 1e-6) || std::abs(normal.normalized().dot(d)) < p.directionalMinimumCosine) continue;
    // The crossing of the zero level along from + t d nearest to the closest-point fit's t.
    const double hint = (x - from).dot(d);
    const double reach = std::abs(hint) + p.directionalSearchMm;
    double best = std::numeric_limits<double>::infinity();
    double previousT = -reach, previous = field.value(toIndex(from + previousT * d));
    for (double t = -reach + step; t <= reach; t += step) {
      const double value = field.value(toIndex(from + t * d));
      if ((previous <= 0) != (value <= 0)) {
        const double crossing = previousT + step * previous / (previous - value);
        if (std::abs(crossing - hint) < std::abs(best - hint)) best = crossing;
      }
      previous = value;
      previousT = t;
    }
    if (!std::isfinite(best) || std::abs(best - hint) > p.directionalSearchMm) continue;
    match.targets.used[i] = true;
    match.targets.points[i] = from + best * d;
    ++match.matched;
  }
  return match;
}

/// The membrane carries each node to its counterpart, and its equilibrium leaves the node short of
/// the boundary by the membrane's own pull (about 1 mm at the bottom of a 20 mm sink on a 4 mm
/// mesh): the correspondence is the membrane's, the position the boundary's. Each node matched
/// along the sinking direction is put on its point. The closest-point nodes stay where the membrane
/// left them: pinned to the segmentation's boundary they follow its errors (on a sphere whose cap
/// the segmentation eroded by 4 mm, the cap's error grew from 0.88 to 1.25 mm). Nodes left free, or
/// placed by the image term, or where the segmentation did not show the expected contrast, stay.
/// Returns the nodes kept at the membrane's position because snapping turned a triangle over.
std::size_t snapOntoBoundary(FitOutcome& fit, const PointTargets& targets, const Eigen::MatrixXd& rest,
                             const std::vector<std::array<vtkIdType, 3>>& triangles,
                             const std::vector<unsigned char>& freeReason, const ActiveSurfaceParameters& p)
{
  const Eigen::MatrixXd membranePositions = fit.positions;
  for (Eigen::Index i = 0; i < fit.positions.rows(); ++i) {
    const std::size_t node = std::size_t(i);
    // Only where the segmentation showed the expected contrast: a boundary the image doubts is no
    // place to pin a node on.
    if (freeReason[node] != 0 || fit.imageUsed[node] || fit.residuals[node] > p.unmatchedResidualMm || fit.plausible[node] == 0) continue;
    if (!targets.used.empty() && targets.used[node]) fit.positions.row(i) = targets.points[node].transpose();
  }
  // Where this turns a triangle over (two neighbours matched to points of a rough boundary far
  // apart), its corners keep the membrane's positions; again, until none does.
  const std::size_t n = std::size_t(rest.rows());
  std::vector<Vec> from(n), to(n);
  for (std::size_t i = 0; i < n; ++i) from[i] = rest.row(Eigen::Index(i)).transpose();
  std::size_t unsnapped = 0;
  for (int round = 0; round < 5; ++round) {
    for (std::size_t i = 0; i < n; ++i) to[i] = fit.positions.row(Eigen::Index(i)).transpose();
    std::size_t reverted = 0;
    for (const auto& t : triangles) {
      if (triangleNormal(from, t).dot(triangleNormal(to, t)) > 0) continue;
      for (vtkIdType corner : t) {
        if (fit.positions.row(corner) != membranePositions.row(corner)) {
          fit.positions.row(corner) = membranePositions.row(corner);
          ++reverted;
        }
      }
    }
    unsnapped += reverted;
    if (reverted == 0) break;
  }
  return unsnapped;
}

void ActiveSurfaceParameters::validate() const
{
  auto require = [](bool ok, const std::string& what) {
    if (!ok) throw InputError("surface: " + what);
  };
  require(std::isfinite(membraneWeight) && membraneWeight >= 0, "the membrane weight must be finite and >= 0");
  require(std::isfinite(bendingWeight) && bendingWeight >= 0, "the bending weight must be finite and >= 0");
  require(std::isfinite(timeStep) && timeStep > 0 && timeStep <= 10, "the time step must be in (0, 10]");
  require(std::isfinite(maximumStepMm) && maximumStepMm > 0 && maximumStepMm <= 20, "the largest step must be in (0, 20] mm");
  require(maximumIterations >= 1 && maximumIterations <= 100000, "the iteration limit must be in [1, 100000]");
  require(std::isfinite(convergenceMm) && convergenceMm > 0, "the convergence threshold must be > 0 mm");
  require(twoSidedMinimumShare >= 0 && twoSidedMinimumShare <= 0.5, "the two-sided share must be within 0 to 0.5");
  require(std::isfinite(distanceSmoothingMm) && distanceSmoothingMm >= 0 && distanceSmoothingMm <= 10,
          "the distance smoothing must be in [0, 10] mm");
  require(std::isfinite(imageWeight) && imageWeight >= 0 && imageWeight <= 1, "the image weight must be in [0, 1]");
  require(std::isfinite(imageSearchMm) && imageSearchMm > 0 && imageSearchMm <= 20, "the image search range must be in (0, 20] mm");
  require(std::isfinite(imageTrustMm) && imageTrustMm > 0, "the image trust range must be > 0 mm");
  require(std::isfinite(unmatchedResidualMm) && unmatchedResidualMm > 0, "the unmatched residual must be > 0 mm");
  require(std::isfinite(resectedFraction) && resectedFraction >= 0 && resectedFraction <= 1, "the resected fraction must be in [0, 1]");
  require(std::isfinite(boundaryOffsetWarningMm) && boundaryOffsetWarningMm >= 0, "the boundary offset's warning must be >= 0 mm");
  require(std::isfinite(boundaryOffsetWarningVoxels) && boundaryOffsetWarningVoxels >= 0,
          "the boundary offset's warning must be >= 0 voxels");
  require(boundaryOffsetMinimumShare >= 0 && boundaryOffsetMinimumShare <= 1, "the boundary offset's share must be in [0, 1]");
  require(std::isfinite(restBandMm) && restBandMm >= 0 && restBandMm <= 5, "the rest band must be in [0, 5] mm");
  require(restBandSmoothingPasses <= 100, "the rest band's smoothing passes must be at most 100");
  require(!brainLabels.empty(), "no brain labels");
}

namespace {

/// What the stage needs of the preoperative mesh: each label's volume (ml), the tumour's nodes and
/// the brain labels it holds.
struct MeshContents {
  std::map<int, double> volumeMl;
  std::set<vtkIdType> tumourNodes;
  std::set<int> meshedBrain;
};

MeshContents meshContentsOf(vtkUnstructuredGrid* mesh, vtkDataArray* cellLabels, const std::set<int>& brain,
                            const ActiveSurfaceParameters& p, const std::string& meshName)
{
  MeshContents contents;
  vtkNew<vtkIdList> ids;
  for (vtkIdType c = 0; c < mesh->GetNumberOfCells(); ++c) {
    const int label = int(std::lround(cellLabels->GetComponent(c, 0)));
    mesh->GetCellPoints(c, ids);
    if (ids->GetNumberOfIds() != 4) throw InputError(meshName + ": cell " + std::to_string(c) + " is not a tetrahedron");
    double q[4][3];
    for (int v = 0; v < 4; ++v) mesh->GetPoint(ids->GetId(v), q[v]);
    Vec a(q[1][0] - q[0][0], q[1][1] - q[0][1], q[1][2] - q[0][2]), b(q[2][0] - q[0][0], q[2][1] - q[0][1], q[2][2] - q[0][2]),
      e(q[3][0] - q[0][0], q[3][1] - q[0][1], q[3][2] - q[0][2]);
    contents.volumeMl[label] += std::abs(a.dot(b.cross(e))) / 6000.0;
    if (label == p.tumourLabel) {
      for (vtkIdType v = 0; v < 4; ++v) contents.tumourNodes.insert(ids->GetId(v));
    }
  }
  for (int l : brain) {
    if (contents.volumeMl.count(l)) contents.meshedBrain.insert(l);
  }
  if (contents.meshedBrain.empty()) throw InputError(meshName + ": the mesh holds none of the brain labels (2, 3, 4)");
  return contents;
}

/// The preoperative brain surface of the mesh: its polygons, triangles and edges, its points and
/// the mesh node of each.
struct BrainSurface {
  vtkSmartPointer<vtkPolyData> polyData;
  SurfaceTopology topology;
  vtkDataArray* meshNodeIds = nullptr;
  std::vector<Vec> points;

  std::size_t size() const { return points.size(); }
  long meshNode(std::size_t i) const { return std::lround(meshNodeIds->GetComponent(vtkIdType(i), 0)); }
};

BrainSurface brainSurfaceOf(vtkUnstructuredGrid* mesh, const std::set<int>& meshedBrain, const std::string& meshName)
{
  BrainSurface surface;
  surface.polyData = boundarySurface(mesh, meshedBrain);
  surface.topology = topologyOf(surface.polyData, meshName);
  const std::size_t n = std::size_t(surface.polyData->GetNumberOfPoints());
  if (n < 4) throw InputError(meshName + ": the brain surface of the mesh is empty");
  surface.meshNodeIds = surface.polyData->GetPointData()->GetArray("MeshNodeId");
  surface.points.resize(n);
  for (std::size_t i = 0; i < n; ++i) surface.polyData->GetPoint(vtkIdType(i), surface.points[i].data());
  return surface;
}

/// K, the surface's graph Laplacian: each node's degree on the diagonal, -1 for each edge.
Eigen::SparseMatrix<double> graphLaplacian(const SurfaceTopology& topology, std::size_t n)
{
  const Eigen::Index size = Eigen::Index(n);
  Eigen::SparseMatrix<double> laplacian(size, size);
  std::vector<Eigen::Triplet<double>> entries;
  std::vector<double> degree(n, 0);
  for (const auto& [a, b] : topology.edges) {
    entries.emplace_back(a, b, -1.0);
    entries.emplace_back(b, a, -1.0);
    degree[std::size_t(a)] += 1;
    degree[std::size_t(b)] += 1;
  }
  for (std::size_t i = 0; i < n; ++i) entries.emplace_back(Eigen::Index(i), Eigen::Index(i), degree[i]);
  laplacian.setFromTriplets(entries.begin(), entries.end());
  return laplacian;
}

Eigen::MatrixXd rowsOf(const std::vector<Vec>& points)
{
  Eigen::MatrixXd rows(Eigen::Index(points.size()), 3);
  for (std::size_t i = 0; i < points.size(); ++i) rows.row(Eigen::Index(i)) = points[i].transpose();
  return rows;
}

/// The preoperative boundary an earlier scan of the same case found (its surface's "PreopBoundary"),
/// checked to belong to the same mesh nodes; written into `boundary`.
void readPreopBoundary(vtkPolyData* previousSurface, const BrainSurface& surface, const ActiveSurfaceInputNames& names,
                       Eigen::MatrixXd& boundary)
{
  const std::size_t n = surface.size();
  vtkDataArray* found = previousSurface->GetPointData()->GetArray("PreopBoundary");
  vtkDataArray* previousIds = previousSurface->GetPointData()->GetArray("MeshNodeId");
  if (!found || found->GetNumberOfComponents() != 3 || !previousIds) {
    throw InputError(names.previousSurface + ": no point arrays \"PreopBoundary\" (3 components) and \"MeshNodeId\"");
  }
  if (previousSurface->GetNumberOfPoints() != vtkIdType(n)) {
    throw InputError(names.previousSurface + ": " + std::to_string(previousSurface->GetNumberOfPoints()) +
                     " surface nodes, not the " + std::to_string(n) + " of " + names.mesh + ": another mesh");
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (std::lround(previousIds->GetComponent(vtkIdType(i), 0)) != surface.meshNode(i)) {
      throw InputError(names.previousSurface + ": surface node " + std::to_string(i) + " is another mesh node than in " + names.mesh);
    }
    for (int d = 0; d < 3; ++d) {
      const double value = found->GetComponent(vtkIdType(i), d);
      if (!std::isfinite(value)) throw InputError(names.previousSurface + ": a PreopBoundary value is not finite");
      boundary(Eigen::Index(i), d) = value;
    }
  }
}

/// The same active surface run on the preoperative labels, from `start`: where the preoperative
/// brain boundary is at each node. Only the labels around the surface are used (distance maps are
/// the stage's main cost).
FitOutcome fitPreopBoundary(const LabelImage& preopLabels, const BrainSurface& surface, const std::set<int>& brain,
                            const MembraneStep& membrane, const Eigen::MatrixXd& start, const ActiveSurfaceParameters& p,
                            const std::string& preopLabelsName)
{
  const std::size_t n = surface.size();
  Warnings ignored;
  std::vector<Vec> indices(n);
  const PreopToIntraopIndex toFullIndex = physicalToIndexOf(ImageGeometry::of(&preopLabels));
  for (std::size_t i = 0; i < n; ++i) indices[i] = toFullIndex(surface.points[i]);
  const LabelImage::Pointer around = cropped(preopLabels, regionAround(ImageGeometry::of(&preopLabels), indices, PreopCropMarginMm));
  const MaskImage::Pointer preopMask = targetBrainMask(*around, brain, preopLabelsName, ignored);
  const ScalarImage::Pointer preopDistance = smoothed(boundaryDistanceMm(preopMask), p.distanceSmoothingMm);
  const TrilinearVolume preopField(*preopDistance);
  const PreopToIntraopIndex toPreopIndex = physicalToIndexOf(ImageGeometry::of(around.GetPointer()));
  std::vector<unsigned char> none(n, 0);
  return fitSurface(membrane, start, preopField, toPreopIndex, nullptr, none, p);
}

/// Whether the tumour is resected: its volume in the intraoperative labels against the mesh's.
bool tumourIsResected(const LabelImage& intraopLabels, const ImageGeometry& grid, const MeshContents& contents,
                      const ActiveSurfaceParameters& p)
{
  if (!contents.volumeMl.count(p.tumourLabel)) return false;
  std::size_t tumourVoxels = 0;
  const LabelPixel* l = intraopLabels.GetBufferPointer();
  for (std::size_t i = 0, count = grid.numberOfVoxels(); i < count; ++i) tumourVoxels += l[i] == p.tumourLabel;
  const double voxelMl = grid.spacing[0] * grid.spacing[1] * grid.spacing[2] / 1000.0;
  return double(tumourVoxels) * voxelMl < p.resectedFraction * contents.volumeMl.at(p.tumourLabel);
}

/// Why each node is free before matching: the resected tumour's nodes, and the nodes outside what
/// the field of view covers (a slab covers part of the brain), left to the elastic model or held at
/// rest. Counts the covered nodes into `result`.
std::vector<unsigned char> freeReasonsBeforeMatching(const BrainSurface& surface, const std::set<vtkIdType>& tumourNodes,
                                                     const PreopToIntraopIndex& toFullIndex, const ImageGeometry& grid,
                                                     const ActiveSurfaceParameters& p, ActiveSurfaceResult& result)
{
  std::vector<unsigned char> freeReason(surface.size(), 0);
  for (std::size_t i = 0; i < surface.size(); ++i) {
    const vtkIdType node = vtkIdType(surface.meshNode(i));
    if (result.tumourResected && tumourNodes.count(node)) freeReason[i] = ResectedTumour;
    if (!TrilinearVolume::insideGrid(toFullIndex(surface.points[i]), grid)) {
      freeReason[i] = p.holdOutsideFieldOfView ? HeldOutsideImage : OutsideImage;
    } else {
      ++result.coveredSurfaceNodes;
    }
  }
  return freeReason;
}

/// The intraoperative target around the surface: the brain's (smoothed) signed distance map on a
/// crop of the labels, and the map from the model frame to the crop's indices.
struct IntraopTarget {
  itk::ImageRegion<3> region;
  LabelImage::Pointer labels;
  ScalarImage::Pointer distance;
  std::unique_ptr<TrilinearVolume> field; ///< samples `distance`
  ImageGeometry grid;
  PreopToIntraopIndex toIndex;
};

IntraopTarget intraopTargetAround(const LabelImage& intraopLabels, const std::vector<Vec>& indices, const std::set<int>& brain,
                                  const SpatialTransform& rigidIntraopToPreop, const ActiveSurfaceParameters& p,
                                  const std::string& labelsName, Warnings& warnings)
{
  IntraopTarget target;
  target.region = regionAround(ImageGeometry::of(&intraopLabels), indices, CropMarginMm);
  target.labels = cropped(intraopLabels, target.region);
  const MaskImage::Pointer mask = targetBrainMask(*target.labels, brain, labelsName, warnings);
  target.distance = smoothed(boundaryDistanceMm(mask), p.distanceSmoothingMm);
  target.field = std::make_unique<TrilinearVolume>(*target.distance);
  target.grid = ImageGeometry::of(target.labels.GetPointer());
  target.toIndex = preopToIntraopIndex(rigidIntraopToPreop, target.grid);
  return target;
}

/// The image term's expected grey levels just inside and just outside the brain, from the
/// segmentation's boundary band; the figures go into `result`.
std::unique_ptr<ImageEdgeTerm> imageEdgeTermOf(const ScalarImage& intraopImage, const IntraopTarget& target,
                                               const ActiveSurfaceParameters& p, ActiveSurfaceResult& result)
{
  auto edges = std::make_unique<ImageEdgeTerm>();
  const ScalarImage::Pointer imageAround = cropped(intraopImage, target.region);
  const float* d = target.distance->GetBufferPointer();
  const float* v = imageAround->GetBufferPointer();
  const LabelPixel* l = target.labels->GetBufferPointer();
  std::vector<double> inside, outsideBand, fluid, parenchyma;
  for (std::size_t i = 0, count = target.grid.numberOfVoxels(); i < count; ++i) {
    if (d[i] >= -3.0f && d[i] <= -1.0f) inside.push_back(v[i]);
    else if (d[i] >= 1.0f && d[i] <= 3.0f) outsideBand.push_back(v[i]);
    if (l[i] == p.fluidLabel) fluid.push_back(v[i]);
    else if (l[i] == p.parenchymaLabel) parenchyma.push_back(v[i]);
  }
  result.expectedInsideIntensity = median(inside);
  result.expectedOutsideIntensity = median(outsideBand);
  // Two-sided surroundings only where this scan's fluid is brighter than its parenchyma (T2):
  // in T1 a band outside that holds brain (a segmentation eroded or moved into it) is an error
  // for the image term to catch, not a second side.
  result.fluidBrighterThanParenchyma = !fluid.empty() && !parenchyma.empty() && median(fluid) > median(parenchyma);
  edges->sides = outsideSides(inside, outsideBand, result.fluidBrighterThanParenchyma ? p.twoSidedMinimumShare : 0.5 + 1e-9,
                              result.outsideBrighterShare);
  result.outsideSides = edges->sides.size();
  edges->intensity = std::make_unique<TrilinearVolume>(*imageAround);
  edges->keepAlive = imageAround;
  return edges;
}

/// The active surface's fit onto the intraoperative boundary, and (when asked) the matches along
/// the sinking direction.
struct IntraopFit {
  FitOutcome fit;
  SinkingDirectionMatch along;
};

IntraopFit fitIntraopBoundary(const MembraneStep& membrane, const Eigen::MatrixXd& preopBoundary, const IntraopTarget& target,
                              const ImageEdgeTerm* edges, const std::vector<unsigned char>& freeReason,
                              const ActiveSurfaceParameters& p, ActiveSurfaceResult& result)
{
  IntraopFit out;
  out.fit = fitSurface(membrane, preopBoundary, *target.field, target.toIndex, edges, freeReason, p);
  result.iterations = out.fit.iterations;
  if (p.matchAlongSinkingDirection) {
    out.along = matchAlongSinkingDirection(preopBoundary, out.fit, *target.field, target.toIndex, freeReason, p);
    result.sinkingDirection = {out.along.direction[0], out.along.direction[1], out.along.direction[2]};
    result.directionalNodes = out.along.matched;
    if (out.along.matched > 0) {
      const Eigen::MatrixXd start = out.fit.positions - preopBoundary;
      out.fit = fitSurface(membrane, preopBoundary, *target.field, target.toIndex, edges, freeReason, p, &start, &out.along.targets);
      result.iterations += out.fit.iterations;
    }
  }
  result.converged = out.fit.converged;
  return out;
}

void warnIfNotConverged(const FitOutcome& preopFit, bool preopFitted, const ActiveSurfaceParameters& p, ActiveSurfaceResult& result)
{
  if (!result.converged) {
    result.warnings.push_back("surface: the active surface did not converge in " + std::to_string(p.maximumIterations) +
                              " iterations");
  }
  if (preopFitted && !preopFit.converged) {
    result.warnings.push_back("surface: the fit to the preoperative boundary did not converge in " +
                              std::to_string(p.maximumIterations) + " iterations");
  }
}

/// Leaves free the nodes that stayed far from the boundary, counts each reason and the residual
/// figures; refuses a fit where fewer than half the covered nodes found the boundary.
void summariseMatch(const FitOutcome& fit, const std::vector<double>& initialResiduals, std::vector<unsigned char>& freeReason,
                    const ActiveSurfaceParameters& p, ActiveSurfaceResult& result)
{
  std::vector<double> residuals, before;
  for (std::size_t i = 0; i < freeReason.size(); ++i) {
    if (freeReason[i] == 0 && fit.residuals[i] > p.unmatchedResidualMm) freeReason[i] = 3;
    switch (freeReason[i]) {
    case 0:
      residuals.push_back(fit.residuals[i]);
      before.push_back(initialResiduals[i]);
      result.imageTermNodes += fit.imageUsed[i];
      break;
    case ResectedTumour: ++result.freeResected; break;
    case OutsideImage: ++result.freeOutsideImage; break;
    case HeldOutsideImage: ++result.heldOutsideImage; break;
    default: ++result.freeUnmatched; break;
    }
  }
  result.imposedNodes = residuals.size() + result.heldOutsideImage;
  if (residuals.size() < result.coveredSurfaceNodes / 2) {
    std::ostringstream m;
    m << "surface: only " << residuals.size() << " of the " << result.coveredSurfaceNodes
      << " brain surface nodes inside the intraoperative image found its brain boundary; the segmentation does not match "
         "the preoperative brain";
    throw MethodError(m.str());
  }
  if (result.freeUnmatched > 0) {
    std::ostringstream w;
    w << "surface: " << result.freeUnmatched << " surface nodes stayed farther than " << p.unmatchedResidualMm
      << " mm from the intraoperative brain and are left free";
    result.warnings.push_back(w.str());
  }
  result.meanResidualMm = mean(residuals);
  result.initialMeanResidualMm = mean(before);
  result.p95ResidualMm = percentile(residuals, 0.95);
  result.maxResidualMm = *std::max_element(residuals.begin(), residuals.end());
}

/// Refuses (MethodError) a surface that folded: more than 1 % of its triangles reversed; warns of fewer.
void requireUnfolded(const Eigen::MatrixXd& preopBoundary, const Eigen::MatrixXd& positions, const SurfaceTopology& topology,
                     ActiveSurfaceResult& result)
{
  const std::size_t n = std::size_t(preopBoundary.rows());
  std::vector<Vec> from(n), to(n);
  for (std::size_t i = 0; i < n; ++i) {
    from[i] = preopBoundary.row(Eigen::Index(i)).transpose();
    to[i] = positions.row(Eigen::Index(i)).transpose();
  }
  for (const auto& t : topology.triangles) result.flippedTriangles += triangleNormal(from, t).dot(triangleNormal(to, t)) <= 0;
  if (result.flippedTriangles > topology.triangles.size() / 100) {
    throw MethodError("surface: the active surface folded (" + std::to_string(result.flippedTriangles) +
                      " triangles reversed); raise the membrane or bending weight");
  }
  if (result.flippedTriangles > 0) {
    result.warnings.push_back("surface: " + std::to_string(result.flippedTriangles) + " surface triangles reversed their orientation");
  }
}

/// The membrane's equilibrium leaves each node short of its target by the membrane's own pull:
/// where the pull is linear (within the capped step), (I + alpha K + beta K^2) v = t, so the
/// displacement is v = F t with F a low-pass filter of the targets' displacements t. F takes off
/// the noise of the segmentation's boundary and, with it, part of every motion whose curvature is
/// large for the mesh: the bottom of a deep sink (about 1 mm at 20 mm on a 4 mm mesh), always
/// short, always the same way. Filtering the residual once more and adding it (Tukey's twicing:
/// v + F (t - v) = (2F - F^2) t) leaves a smooth motion's loss at (1 - F)^2 instead of 1 - F,
/// while what F damps strongly (the boundary's voxel-scale roughness) stays damped.
/// The residual is each matched node's final pull (free nodes: none); `unitStep` is the membrane
/// with tau = 1 (F itself, MembraneFilter). Refreshes the matched nodes' residuals to the
/// segmentation's boundary (not where the image's edge placed the node). Sets the correction's mean and largest length.
void correctMembraneResidual(FitOutcome& fit, const MembraneStep& unitStep, const IntraopTarget& target,
                             const std::vector<unsigned char>& freeReason, const ActiveSurfaceParameters& p,
                             ActiveSurfaceResult& result)
{
  const Eigen::Index n = fit.positions.rows();
  Eigen::MatrixXd residual = Eigen::MatrixXd::Zero(n, 3);
  for (Eigen::Index i = 0; i < n; ++i) {
    const std::size_t node = std::size_t(i);
    if (freeReason[node] == 0 && fit.residuals[node] <= p.unmatchedResidualMm) residual.row(i) = fit.pull.row(i);
  }
  const Eigen::MatrixXd correction = unitStep.solve(residual);
  double sum = 0, largest = 0;
  std::size_t corrected = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const std::size_t node = std::size_t(i);
    if (freeReason[node] != 0) continue;
    fit.positions.row(i) += correction.row(i);
    const double length = correction.row(i).norm();
    sum += length;
    largest = std::max(largest, length);
    ++corrected;
  }
  const std::vector<double> refreshed = residualsAt(fit.positions, *target.field, target.toIndex);
  for (std::size_t i = 0; i < refreshed.size(); ++i) {
    if (freeReason[i] == 0 && !fit.imageUsed[i]) fit.residuals[i] = refreshed[i];
  }
  result.residualCorrectionMeanMm = corrected ? sum / double(corrected) : 0.0;
  result.residualCorrectionMaxMm = largest;
}

/// Unit normals of the surface at `positions` (each node's triangles' normals, area-weighted),
/// pointing away from its centroid on the whole: outward on a closed brain surface.
Eigen::MatrixXd outwardNormals(const Eigen::MatrixXd& positions, const SurfaceTopology& topology)
{
  Eigen::MatrixXd normals = Eigen::MatrixXd::Zero(positions.rows(), 3);
  for (const auto& t : topology.triangles) {
    const Eigen::RowVector3d a = positions.row(t[0]), b = positions.row(t[1]), c = positions.row(t[2]);
    const Eigen::RowVector3d areaNormal = (b - a).cross(c - a);
    for (vtkIdType corner : t) normals.row(corner) += areaNormal;
  }
  const Eigen::RowVector3d centroid = positions.colwise().mean();
  double outwardness = 0;
  for (Eigen::Index i = 0; i < positions.rows(); ++i) {
    const double length = normals.row(i).norm();
    if (length > 0) normals.row(i) /= length;
    outwardness += normals.row(i).dot(positions.row(i) - centroid);
  }
  if (outwardness < 0) normals = -normals;
  return normals;
}

/// The segmentation's offset at the brain boundary. A craniotomy moves part of the brain surface;
/// the rest stays against the skull. Over the nodes the segmentation placed (matched, not by the
/// image's edge) the median move along the outward normal is then what the whole boundary shares:
/// where this scan's classification puts the brain's edge against where the preoperative labels put
/// it (T2's bright fluid against the cortex: 0.85-1.09 mm inside on the scenarios), or a change of the
/// whole brain. The solve carries it into the brain beneath the whole surface, less what the rest
/// band holds (holdAtRest; README, "Active surface"); beyond `warningMm` a warning says so. It is not taken off: where the
/// brain moved the segmentation's error can be the other way (T2's gap fluid called brain), and a
/// uniform correction doubled the boundary's error there. Not measured when those nodes cover less
/// than `boundaryOffsetMinimumShare` of the surface (a slab may see mostly the region that moved).
void measureSegmentationOffset(const FitOutcome& fit, const Eigen::MatrixXd& preopBoundary, const SurfaceTopology& topology,
                               const std::vector<unsigned char>& freeReason, double warningMm, const ActiveSurfaceParameters& p,
                               ActiveSurfaceResult& result)
{
  result.boundaryOffsetWarningMm = warningMm;
  const Eigen::MatrixXd normals = outwardNormals(preopBoundary, topology);
  std::vector<double> normalMoves; // of the nodes the segmentation placed
  for (Eigen::Index i = 0; i < preopBoundary.rows(); ++i) {
    const std::size_t node = std::size_t(i);
    if (freeReason[node] != 0 || fit.imageUsed[node]) continue;
    normalMoves.push_back((fit.positions.row(i) - preopBoundary.row(i)).dot(normals.row(i)));
  }
  if (normalMoves.empty() || double(normalMoves.size()) < p.boundaryOffsetMinimumShare * double(preopBoundary.rows())) return;
  result.boundaryOffsetMm = median(normalMoves);
  result.boundaryOffsetNodes = normalMoves.size();
  if (!(std::abs(result.boundaryOffsetMm) > warningMm)) return;
  std::ostringstream w;
  w << "surface: over most of the brain surface the intraoperative brain boundary lies " << std::fixed << std::setprecision(1)
    << std::abs(result.boundaryOffsetMm) << " mm " << (result.boundaryOffsetMm < 0 ? "inside" : "outside")
    << " the preoperative one (median of " << normalMoves.size()
    << " surface nodes): this scan's classification draws the brain's edge elsewhere than the preoperative labels, or the "
       "whole brain changed; the update moves the brain beneath its whole surface by about as much, less what the rest band "
       "holds (surface.rest_band_mm; check the classification)";
  result.warnings.push_back(w.str());
}

/// The rest band (ActiveSurfaceParameters::restBandMm): each matched node's displacement u becomes
/// s u, s = clamp((|m| - band) / band, 0, 1) with m the surface's local mean move at the node (u
/// filtered by the membrane's F, `filter`, `restBandSmoothingPasses` times): held at rest below the band, all of it
/// beyond twice the band, a continuous ramp between (a step would tear the imposed field between
/// neighbours). The local mean, not the node's own move: the segmentation's boundary noise changes
/// from node to node and averages out, a real motion does not, so the rim of a region that moved
/// keeps its move. Counts the nodes held and those scaled, and the median local move over the
/// matched nodes (over a surface most of which did not move: the noise the band faces).
void holdAtRest(Eigen::MatrixXd& u, const std::vector<unsigned char>& freeReason, const MembraneStep& filter,
                const ActiveSurfaceParameters& p, ActiveSurfaceResult& result)
{
  if (!(p.restBandMm > 0)) return;
  Eigen::MatrixXd local = u;
  for (unsigned pass = 0; pass < p.restBandSmoothingPasses; ++pass) local = filter.solve(local);
  std::vector<double> localMoves;
  for (std::size_t i = 0; i < freeReason.size(); ++i) {
    if (freeReason[i] == Matched) localMoves.push_back(local.row(Eigen::Index(i)).norm());
  }
  if (!localMoves.empty()) result.restLocalMoveMedianMm = median(localMoves);
  for (std::size_t i = 0; i < freeReason.size(); ++i) {
    if (freeReason[i] != Matched) continue;
    const Eigen::Index row = Eigen::Index(i);
    const double scale = std::clamp((local.row(row).norm() - p.restBandMm) / p.restBandMm, 0.0, 1.0);
    if (scale >= 1.0) continue;
    u.row(row) *= scale;
    ++(scale > 0 ? result.restScaledNodes : result.restHeldNodes);
  }
}

/// Each node's displacement from its preoperative boundary point: snapped onto the target boundary
/// where asked, zero where held outside the image, held or scaled down within the rest band; the
/// surface must not have folded.
Eigen::MatrixXd surfaceDisplacements(IntraopFit& fitted, const Eigen::MatrixXd& preopBoundary, const SurfaceTopology& topology,
                                     const MembraneStep& filter, const std::vector<unsigned char>& freeReason,
                                     const ActiveSurfaceParameters& p, ActiveSurfaceResult& result)
{
  FitOutcome& fit = fitted.fit;
  if (p.snapToBoundary) {
    result.unsnappedNodes = snapOntoBoundary(fit, fitted.along.targets, preopBoundary, topology.triangles, freeReason, p);
  }
  Eigen::MatrixXd u = fit.positions - preopBoundary;
  for (std::size_t i = 0; i < freeReason.size(); ++i) {
    if (freeReason[i] == HeldOutsideImage) u.row(Eigen::Index(i)).setZero();
  }
  holdAtRest(u, freeReason, filter, p, result);
  fit.positions = preopBoundary + u;
  requireUnfolded(preopBoundary, fit.positions, topology, result);
  return u;
}

/// The deformed surface: each mesh node moved by its displacement, with the arrays the contract
/// names, and "PreopBoundary" for the next scan (deformBrainSurface's previousSurface).
vtkSmartPointer<vtkPolyData> deformedSurface(const BrainSurface& initial, const Eigen::MatrixXd& u, const Eigen::MatrixXd& preopBoundary,
                                             const std::vector<unsigned char>& freeReason, ActiveSurfaceResult& result)
{
  auto surface = vtkSmartPointer<vtkPolyData>::New();
  vtkNew<vtkPoints> points;
  points->SetDataTypeToDouble();
  vtkNew<vtkDoubleArray> displacement, magnitude;
  displacement->SetName("Displacement");
  displacement->SetNumberOfComponents(3);
  magnitude->SetName("DisplacementMagnitude");
  vtkNew<vtkIntArray> nodeIds, imposed;
  nodeIds->SetName("MeshNodeId");
  imposed->SetName("Imposed");
  std::vector<double> magnitudes;
  for (std::size_t i = 0; i < initial.size(); ++i) {
    const Vec d = u.row(Eigen::Index(i)).transpose();
    const Vec moved = initial.points[i] + d;
    points->InsertNextPoint(moved.data());
    displacement->InsertNextTuple(d.data());
    magnitude->InsertNextValue(d.norm());
    magnitudes.push_back(d.norm());
    nodeIds->InsertNextValue(int(initial.meshNode(i)));
    imposed->InsertNextValue(freeReason[i] == Matched || freeReason[i] == HeldOutsideImage ? 1 : 0);
  }
  result.meanDisplacementMm = mean(magnitudes);
  result.maxDisplacementMm = *std::max_element(magnitudes.begin(), magnitudes.end());
  surface->SetPoints(points);
  vtkNew<vtkCellArray> polys; // a copy: the membrane's surface is kept for the next fit, unchanged
  polys->DeepCopy(initial.polyData->GetPolys());
  surface->SetPolys(polys);
  surface->GetPointData()->AddArray(displacement);
  surface->GetPointData()->AddArray(magnitude);
  surface->GetPointData()->AddArray(nodeIds);
  surface->GetPointData()->AddArray(imposed);
  vtkNew<vtkDoubleArray> preopBoundaryArray;
  preopBoundaryArray->SetName("PreopBoundary");
  preopBoundaryArray->SetNumberOfComponents(3);
  for (std::size_t i = 0; i < initial.size(); ++i) {
    const Vec b = preopBoundary.row(Eigen::Index(i)).transpose();
    preopBoundaryArray->InsertNextTuple(b.data());
  }
  surface->GetPointData()->AddArray(preopBoundaryArray);
  surface->GetPointData()->SetActiveScalars("DisplacementMagnitude");
  return surface;
}

/// Refuses inputs that do not fit together: a non-linear rigid transform, labels off the image's
/// grid, a mesh without cell labels (returned).
vtkDataArray* checkedCellLabels(vtkUnstructuredGrid* mesh, const LabelImage& intraopLabels, const ScalarImage* intraopImage,
                                const SpatialTransform& rigidIntraopToPreop, const ActiveSurfaceInputNames& names)
{
  if (!isLinearTransform(&rigidIntraopToPreop)) throw InputError(names.rigid + ": the rigid transform is not linear");
  const ImageGeometry grid = ImageGeometry::of(&intraopLabels);
  if (intraopImage && !grid.sameGridAs(ImageGeometry::of(intraopImage))) {
    throw InputError(names.labels + ": not on the intraoperative image's grid (" + grid.describe() + " against " +
                     ImageGeometry::of(intraopImage).describe() + ")");
  }
  vtkDataArray* cellLabels = mesh->GetCellData()->GetArray("Label");
  if (!cellLabels) throw InputError(names.mesh + ": the mesh has no cell array \"Label\"");
  return cellLabels;
}
} // namespace

ActiveSurfaceParameters activeSurfaceParametersFrom(const Configuration& configuration)
{
  ActiveSurfaceParameters parameters;
  parameters.membraneWeight = configuration.surfaceMembraneWeight;
  parameters.bendingWeight = configuration.surfaceBendingWeight;
  parameters.imageWeight = configuration.surfaceImageWeight;
  parameters.maximumIterations = configuration.surfaceMaximumIterations;
  parameters.matchAlongSinkingDirection = configuration.surfaceMatchAlongSinkingDirection;
  parameters.snapToBoundary = configuration.surfaceSnapToBoundary;
  parameters.residualCorrection = configuration.surfaceResidualCorrection;
  parameters.holdOutsideFieldOfView = configuration.surfaceHoldOutsideFieldOfView;
  parameters.restBandMm = configuration.surfaceRestBandMm;
  parameters.restBandSmoothingPasses = configuration.surfaceRestBandSmoothingPasses;
  return parameters;
}

namespace {
/// The mesh's brain surface and its membrane, I + tau (alpha K + beta K^2) with K the surface's
/// graph Laplacian, factorised once: what the preoperative and the intraoperative fits move.
struct SurfaceMembrane {
  std::set<int> brain;
  MeshContents contents;
  BrainSurface surface;
  Eigen::SparseMatrix<double> laplacian;
  MembraneStep membrane;

  SurfaceMembrane(vtkUnstructuredGrid* mesh, vtkDataArray* cellLabels, const ActiveSurfaceParameters& p, const std::string& meshName)
    : brain(p.brainLabels.begin(), p.brainLabels.end())
    , contents(meshContentsOf(mesh, cellLabels, brain, p, meshName))
    , surface(brainSurfaceOf(mesh, contents.meshedBrain, meshName))
    , laplacian(graphLaplacian(surface.topology, surface.size()))
    , membrane(laplacian, p)
  {
    if (!membrane.ok()) throw MethodError("surface: the membrane system could not be factorised");
  }
};

/// The fields of ActiveSurfaceParameters a SurfaceMembrane reads: the one list its parameters and
/// its cache key are both made of.
template <class Parameters>
auto membraneFields(Parameters& p)
{
  return std::tie(p.brainLabels, p.tumourLabel, p.timeStep, p.membraneWeight, p.bendingWeight);
}

/// Those fields of `p` alone (every other at its default): the membrane is built from these, so
/// no field it reads can slip past the key.
ActiveSurfaceParameters membraneParametersOf(const ActiveSurfaceParameters& p)
{
  ActiveSurfaceParameters m;
  membraneFields(m) = membraneFields(p);
  return m;
}

/// What a SurfaceMembrane is built from: the mesh's points, its cells (each as its size and node
/// ids) and their labels, and the parameters it reads. Equal keys build the same membrane.
struct SurfaceMembraneKey {
  std::vector<double> points, cellLabels;
  std::vector<vtkIdType> cells;
  ActiveSurfaceParameters parameters; ///< membraneParametersOf

  bool operator==(const SurfaceMembraneKey& other) const
  {
    return points == other.points && cellLabels == other.cellLabels && cells == other.cells &&
           membraneFields(parameters) == membraneFields(other.parameters);
  }
};

SurfaceMembraneKey surfaceMembraneKeyOf(vtkUnstructuredGrid* mesh, vtkDataArray* cellLabels, const ActiveSurfaceParameters& read)
{
  SurfaceMembraneKey key;
  key.points.resize(3 * std::size_t(mesh->GetNumberOfPoints()));
  for (vtkIdType i = 0; i < mesh->GetNumberOfPoints(); ++i) mesh->GetPoint(i, &key.points[3 * std::size_t(i)]);
  key.cells.reserve(5 * std::size_t(mesh->GetNumberOfCells()));
  key.cellLabels.reserve(std::size_t(mesh->GetNumberOfCells()));
  vtkNew<vtkIdList> ids;
  for (vtkIdType c = 0; c < mesh->GetNumberOfCells(); ++c) {
    mesh->GetCellPoints(c, ids);
    key.cells.push_back(ids->GetNumberOfIds());
    for (vtkIdType k = 0; k < ids->GetNumberOfIds(); ++k) key.cells.push_back(ids->GetId(k));
    key.cellLabels.push_back(c < cellLabels->GetNumberOfTuples() ? cellLabels->GetComponent(c, 0) : std::nan(""));
  }
  key.parameters = read;
  return key;
}

/// The mesh's surface membrane, built once for a mesh: a watch session fits its preoperative
/// boundary and every scan's surface on one mesh, and building the membrane (the mesh's brain
/// surface, its edges, the Laplacian, two sparse factorisations) took 0.2-0.25 s of a later scan on
/// one core; comparing the key takes milliseconds. The last one built is kept, whole and never
/// changed (the fits only read it); a mesh of other content builds its own. Never destroyed: VTK
/// objects must not outlive VTK's own state at exit.
std::shared_ptr<const SurfaceMembrane> surfaceMembraneFor(vtkUnstructuredGrid* mesh, vtkDataArray* cellLabels,
                                                         const ActiveSurfaceParameters& p, const std::string& meshName)
{
  struct LastBuilt {
    std::mutex guard;
    std::shared_ptr<const SurfaceMembraneKey> key;
    std::shared_ptr<const SurfaceMembrane> membrane;
  };
  static LastBuilt* const last = new LastBuilt;
  const ActiveSurfaceParameters read = membraneParametersOf(p);
  auto key = std::make_shared<const SurfaceMembraneKey>(surfaceMembraneKeyOf(mesh, cellLabels, read));
  {
    const std::lock_guard<std::mutex> lock(last->guard);
    if (last->membrane && *last->key == *key) return last->membrane;
  }
  auto built = std::make_shared<const SurfaceMembrane>(mesh, cellLabels, read, meshName);
  const std::lock_guard<std::mutex> lock(last->guard);
  last->key = std::move(key);
  last->membrane = built;
  return built;
}
} // namespace

PreoperativeBrainBoundary preoperativeBrainBoundary(vtkUnstructuredGrid* mesh, const LabelImage& preopLabels, const ActiveSurfaceParameters& p,
                                                    const ActiveSurfaceInputNames& names)
{
  p.validate();
  const auto start = std::chrono::steady_clock::now();
  vtkDataArray* cellLabels = mesh ? mesh->GetCellData()->GetArray("Label") : nullptr;
  if (!cellLabels) throw InputError(names.mesh + ": the mesh has no cell array \"Label\"");
  // As deformBrainSurface's first steps: the same surface, membrane and fit.
  const std::shared_ptr<const SurfaceMembrane> membraneOfMesh = surfaceMembraneFor(mesh, cellLabels, p, names.mesh);
  const SurfaceMembrane& model = *membraneOfMesh;
  const BrainSurface& surface = model.surface;
  const std::size_t n = surface.size();
  const Eigen::MatrixXd smoothedStart = taubinSmoothed(rowsOf(surface.points), model.laplacian, p.restSmoothingIterations);
  const FitOutcome fit = fitPreopBoundary(preopLabels, surface, model.brain, model.membrane, smoothedStart, p, names.preopLabels);
  PreoperativeBrainBoundary boundary;
  ActiveSurfaceResult figures;
  boundary.surface = deformedSurface(surface, Eigen::MatrixXd::Zero(Eigen::Index(n), 3), fit.positions,
                                     std::vector<unsigned char>(n, Matched), figures);
  figures.converged = true; // no intraoperative fit here: only the preoperative one can fail to converge
  warnIfNotConverged(fit, true, p, figures);
  boundary.warnings = figures.warnings;
  boundary.seconds = secondsSince(start);
  return boundary;
}

ActiveSurfaceResult deformBrainSurface(vtkUnstructuredGrid* mesh, const LabelImage* preopLabels, const LabelImage& intraopLabels,
                                       const ScalarImage* intraopImage, const SpatialTransform& rigidIntraopToPreop,
                                       const ActiveSurfaceParameters& p, const ActiveSurfaceInputNames& names,
                                       vtkPolyData* previousSurface)
{
  p.validate();
  ActiveSurfaceResult result;
  vtkDataArray* cellLabels = checkedCellLabels(mesh, intraopLabels, intraopImage, rigidIntraopToPreop, names);
  const ImageGeometry grid = ImageGeometry::of(&intraopLabels);

  // -- The preoperative brain surface, what is known of its nodes, and its membrane.
  const std::shared_ptr<const SurfaceMembrane> membraneOfMesh = surfaceMembraneFor(mesh, cellLabels, p, names.mesh);
  const SurfaceMembrane& model = *membraneOfMesh;
  const std::set<int>& brain = model.brain;
  const MeshContents& contents = model.contents;
  const BrainSurface& surface = model.surface;
  const Eigen::SparseMatrix<double>& laplacian = model.laplacian;
  const MembraneStep& membrane = model.membrane;
  const std::size_t n = surface.size();
  const Eigen::MatrixXd initialPositions = rowsOf(surface.points);

  // -- Where the preoperative brain boundary is at each node. The lattice's nodes are only near
  //    it (within a step); the same active surface, run on the preoperative labels, finds it. The
  //    displacement imposed is then intraoperative boundary minus preoperative boundary, so what the
  //    mesh approximates and what the method smooths cancels out, and no shift means no motion.
  const auto targetStart = std::chrono::steady_clock::now();
  const Eigen::MatrixXd smoothedStart = taubinSmoothed(initialPositions, laplacian, p.restSmoothingIterations);
  Eigen::MatrixXd preopBoundary = smoothedStart;
  FitOutcome preopFit;
  preopFit.converged = true;
  if (previousSurface) {
    readPreopBoundary(previousSurface, surface, names, preopBoundary); // an earlier scan of the same case found it
    result.preopBoundarySeconds = secondsSince(targetStart);
  } else if (preopLabels) {
    preopFit = fitPreopBoundary(*preopLabels, surface, brain, membrane, smoothedStart, p, names.preopLabels);
    preopBoundary = preopFit.positions;
    result.preopBoundarySeconds = secondsSince(targetStart);
  }

  // -- The intraoperative target, and which nodes it covers.
  const auto intraopStart = std::chrono::steady_clock::now();
  result.tumourResected = tumourIsResected(intraopLabels, grid, contents, p);
  const PreopToIntraopIndex toFullIndex = preopToIntraopIndex(rigidIntraopToPreop, grid);
  std::vector<Vec> indices(n);
  for (std::size_t i = 0; i < n; ++i) indices[i] = toFullIndex(surface.points[i]);
  std::vector<unsigned char> freeReason = freeReasonsBeforeMatching(surface, contents.tumourNodes, toFullIndex, grid, p, result);
  result.surfaceNodes = n;
  result.coveredBrainMl = coveredBrainVolumeMl(mesh, cellLabels, contents.meshedBrain, toFullIndex, grid, result.meshedBrainMl);
  requireEnoughCoverage(result, p, names.labels);
  const IntraopTarget target = intraopTargetAround(intraopLabels, indices, brain, rigidIntraopToPreop, p, names.labels, result.warnings);
  std::unique_ptr<ImageEdgeTerm> edges;
  if (intraopImage && (p.imageWeight > 0 || p.imageRescue)) edges = imageEdgeTermOf(*intraopImage, target, p, result);
  result.targetSeconds = secondsSince(intraopStart);

  // -- The active surface, from the preoperative boundary onto the intraoperative one.
  const auto iterationStart = std::chrono::steady_clock::now();
  const std::vector<double> initialResiduals = residualsAt(initialPositions, *target.field, target.toIndex);
  IntraopFit fitted = fitIntraopBoundary(membrane, preopBoundary, target, edges.get(), freeReason, p, result);
  warnIfNotConverged(preopFit, preopLabels != nullptr, p, result);
  const MembraneFilter filter(laplacian, membrane, p);
  if (p.residualCorrection) correctMembraneResidual(fitted.fit, filter.step(), target, freeReason, p, result);
  result.iterationSeconds = secondsSince(iterationStart);

  // -- Nodes left free, the figures, and the deformed surface.
  summariseMatch(fitted.fit, initialResiduals, freeReason, p, result);
  // Measured against the preoperative boundary only (without it the mesh's own surface stands in,
  // and its meshing would count as an offset).
  if (preopLabels || previousSurface) {
    const double voxelMm = std::cbrt(grid.spacing[0] * grid.spacing[1] * grid.spacing[2]);
    const double warningMm = std::max(p.boundaryOffsetWarningMm, p.boundaryOffsetWarningVoxels * voxelMm);
    measureSegmentationOffset(fitted.fit, preopBoundary, surface.topology, freeReason, warningMm, p, result);
  }
  const Eigen::MatrixXd u = surfaceDisplacements(fitted, preopBoundary, surface.topology, filter.step(), freeReason, p, result);
  result.surface = deformedSurface(surface, u, preopBoundary, freeReason, result);
  return result;
}

} // namespace brainshift
