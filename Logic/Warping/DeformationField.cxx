#include "DeformationField.h"

#include "AffineResampling.h"
#include "ParallelRanges.h"

#include <itkSmoothingRecursiveGaussianImageFilter.h>

// ITK brings its own Eigen; a second copy in the same translation unit clashes.
#include <itk_eigen.h>
#include ITK_EIGEN(Dense)

#include <vtkCellArray.h>
#include <vtkCellData.h>
#include <vtkDataArray.h>
#include <vtkIdList.h>
#include <vtkPointData.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <future>
#include <memory>
#include <numeric>
#include <stdexcept>
#include <string>

namespace brainshift {

namespace {
using Vec = Eigen::Vector3d;
using Mat = Eigen::Matrix3d;

double secondsSince(std::chrono::steady_clock::time_point start)
{
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

struct GridMaps {
  Mat indexToPhysical; ///< D S
  Vec origin;
  Mat rigidMatrix;     ///< y -> A y + t (intraop -> model frame)
  Vec rigidTranslation;
  Mat modelToIndex;    ///< p -> (D S)^-1 (A^-1 (p - t) - o)
  Vec modelToIndexOffset;
};

GridMaps gridMapsOf(const SpatialTransform& rigid, const ImageGeometry& grid)
{
  GridMaps g;
  const AffineParameters a = affineParametersOf(&rigid);
  Mat D, S = Mat::Zero();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      D(i, j) = grid.direction[unsigned(i)][unsigned(j)];
      g.rigidMatrix(i, j) = a.matrix[i][j];
    }
    S(i, i) = grid.spacing[unsigned(i)];
    g.origin[i] = grid.origin[unsigned(i)];
    g.rigidTranslation[i] = a.translation[i];
  }
  g.indexToPhysical = D * S;
  const Mat physicalToIndex = g.indexToPhysical.inverse();
  const Mat rigidInverse = g.rigidMatrix.inverse();
  g.modelToIndex = physicalToIndex * rigidInverse;
  g.modelToIndexOffset = physicalToIndex * (-rigidInverse * g.rigidTranslation - g.origin);
  return g;
}


ScalarImage::Pointer gaussian(const ScalarImage::Pointer& image, double sigmaMm)
{
  auto smoother = itk::SmoothingRecursiveGaussianImageFilter<ScalarImage, ScalarImage>::New();
  smoother->SetInput(image);
  smoother->SetSigma(sigmaMm);
  smoother->Update();
  ScalarImage::Pointer out = smoother->GetOutput();
  out->DisconnectPipeline();
  return out;
}

/// The intraoperative grid's voxel counts along i, j and k, and a voxel's place in the buffers.
struct VoxelLattice {
  long nx, ny, nz;
  explicit VoxelLattice(const ImageGeometry& grid) : nx(long(grid.size[0])), ny(long(grid.size[1])), nz(long(grid.size[2])) {}
  std::size_t offset(long i, long j, long k) const { return std::size_t(i + nx * (j + ny * k)); }
};

/// The non-rigid correction w = X - p of each intraoperative voxel (model frame, three floats a
/// voxel), and whether the deformed mesh holds the voxel (elsewhere w is the fade).
struct VoxelCorrection {
  std::vector<float> w;
  std::vector<unsigned char> located;
  std::size_t invertedDeformedTetrahedra = 0;
};

/// The mesh's nodes: X in the preoperative (model) frame, and X + u in the intraoperative grid's
/// index space, where the deformed tetrahedra are rasterised.
struct MeshNodes {
  std::vector<Vec> undeformed, deformedIndex;
};

/// A solved mesh's displacement and a linear rigid transform, else InputError naming the mesh.
void requireSolvedMeshAndLinearRigid(vtkDataArray* displacement, const SpatialTransform& rigid, const std::string& meshName)
{
  if (!displacement || displacement->GetNumberOfComponents() != 3) {
    throw InputError(meshName + ": no point array \"Displacement\"; run `brainshift simulate` on this output folder first");
  }
  if (!isLinearTransform(&rigid)) throw InputError("the rigid transform is not linear");
}

/// Calls visit(cell, v) for each tetrahedron of the mesh (v its four point ids); InputError naming
/// the mesh for another cell.
template <class Visit>
void forEachTetrahedron(vtkUnstructuredGrid* mesh, const std::string& meshName, Visit&& visit)
{
  vtkNew<vtkIdList> ids;
  for (vtkIdType c = 0; c < mesh->GetNumberOfCells(); ++c) {
    mesh->GetCellPoints(c, ids);
    if (ids->GetNumberOfIds() != 4) throw InputError(meshName + ": cell " + std::to_string(c) + " is not a tetrahedron");
    const vtkIdType v[4] = {ids->GetId(0), ids->GetId(1), ids->GetId(2), ids->GetId(3)};
    visit(c, v);
  }
}

void checkFieldInputs(vtkDataArray* displacement, const SpatialTransform& rigid, const DeformationFieldParameters& parameters,
                      const std::string& meshName)
{
  requireSolvedMeshAndLinearRigid(displacement, rigid, meshName);
  if (!(parameters.fallbackSigmaMm > 0) || parameters.fallbackSigmaMm > 100) {
    throw InputError("warp: the fallback width must be within 0 to 100 mm");
  }
  if (!(parameters.continuationMaximumMm >= 0) || !(parameters.continuationMinimumMm >= 0) ||
      !(parameters.continuationMaximumCompression > 0 && parameters.continuationMaximumCompression <= 1) ||
      (parameters.continuationMaximumMm > 0 && parameters.continuationMinimumMm > parameters.continuationMaximumMm)) {
    throw InputError("warp: the continuation's band needs 0 <= minimum <= maximum and a compression in (0, 1]");
  }
}

MeshNodes meshNodesOf(vtkUnstructuredGrid* mesh, vtkDataArray* displacement, const GridMaps& maps, const std::string& meshName)
{
  const vtkIdType nodes = mesh->GetNumberOfPoints();
  MeshNodes result;
  result.undeformed.resize(std::size_t(nodes));
  result.deformedIndex.resize(std::size_t(nodes));
  for (vtkIdType i = 0; i < nodes; ++i) {
    Vec x, u;
    mesh->GetPoint(i, x.data());
    displacement->GetTuple(i, u.data());
    if (!u.allFinite()) throw InputError(meshName + ": the displacement of node " + std::to_string(i) + " is not finite");
    result.undeformed[std::size_t(i)] = x;
    result.deformedIndex[std::size_t(i)] = maps.modelToIndex * (x + u) + maps.modelToIndexOffset;
  }
  return result;
}

/// Calls visit(offset, lambda) for each voxel of the lattice whose centre the tetrahedron with
/// corners `q` (index space) holds and `skip(offset)` does not refuse, lambda its barycentric
/// coordinates there (of q[0] first). Nothing for a degenerate tetrahedron.
template <class Skip, class Visit>
void forEachVoxelInTetrahedron(const std::array<Vec, 4>& q, const VoxelLattice& lattice, Skip&& skip, Visit&& visit)
{
  Mat edges;
  for (int k = 0; k < 3; ++k) edges.col(k) = q[std::size_t(k + 1)] - q[0];
  if (std::abs(edges.determinant()) < 1e-12) return;
  const Mat inverse = edges.inverse();
  Vec lo = q[0], hi = q[0];
  for (std::size_t k = 1; k < 4; ++k) {
    lo = lo.cwiseMin(q[k]);
    hi = hi.cwiseMax(q[k]);
  }
  const long i0 = std::max(0L, long(std::ceil(lo[0]))), i1 = std::min(lattice.nx - 1, long(std::floor(hi[0])));
  const long j0 = std::max(0L, long(std::ceil(lo[1]))), j1 = std::min(lattice.ny - 1, long(std::floor(hi[1])));
  const long k0 = std::max(0L, long(std::ceil(lo[2]))), k1 = std::min(lattice.nz - 1, long(std::floor(hi[2])));
  for (long k = k0; k <= k1; ++k) {
    for (long j = j0; j <= j1; ++j) {
      for (long i = i0; i <= i1; ++i) {
        const std::size_t at = lattice.offset(i, j, k);
        if (skip(at)) continue;
        const Vec lambda = inverse * (Vec(double(i), double(j), double(k)) - q[0]);
        const double lambda0 = 1.0 - lambda.sum();
        const double eps = -1e-9;
        if (lambda[0] < eps || lambda[1] < eps || lambda[2] < eps || lambda0 < eps) continue;
        visit(at, std::array<double, 4>{lambda0, lambda[0], lambda[1], lambda[2]});
      }
    }
  }
}

std::array<Vec, 4> deformedCorners(const vtkIdType v[4], const MeshNodes& nodes)
{
  return {nodes.deformedIndex[std::size_t(v[0])], nodes.deformedIndex[std::size_t(v[1])], nodes.deformedIndex[std::size_t(v[2])],
          nodes.deformedIndex[std::size_t(v[3])]};
}

/// Gives each voxel of the deformed tetrahedron `v` (not yet located) its correction, from the
/// barycentric coordinates of its index in the deformed tetrahedron. Index space is an affine image
/// of the model frame, so barycentric coordinates carry over.
void rasteriseDeformedTetrahedron(const vtkIdType v[4], const MeshNodes& nodes, vtkDataArray* displacement,
                                  const VoxelLattice& lattice, VoxelCorrection& out)
{
  const std::array<Vec, 4> q = deformedCorners(v, nodes);
  Mat edges, undeformedEdges;
  for (int k = 0; k < 3; ++k) {
    edges.col(k) = q[std::size_t(k + 1)] - q[0];
    undeformedEdges.col(k) = nodes.undeformed[std::size_t(v[k + 1])] - nodes.undeformed[std::size_t(v[0])];
  }
  if (edges.determinant() * undeformedEdges.determinant() <= 0) ++out.invertedDeformedTetrahedra;
  std::array<Vec, 4> u;
  for (std::size_t k = 0; k < 4; ++k) displacement->GetTuple(v[k], u[k].data());
  forEachVoxelInTetrahedron(
    q, lattice, [&](std::size_t at) { return out.located[at] != 0; },
    [&](std::size_t at, const std::array<double, 4>& lambda) {
      out.located[at] = 1;
      // X - p = -(sum lambda_k u_k): the preoperative point minus the deformed one.
      const Vec w = -(lambda[0] * u[0] + lambda[1] * u[1] + lambda[2] * u[2] + lambda[3] * u[3]);
      for (int d = 0; d < 3; ++d) out.w[3 * at + std::size_t(d)] = float(w[d]);
    });
}

/// Locates every voxel's model-frame point in the deformed mesh by rasterising each deformed
/// tetrahedron over the voxels of its box; the first tetrahedron to hold a voxel gives its correction.
VoxelCorrection correctionInsideDeformedMesh(vtkUnstructuredGrid* mesh, vtkDataArray* displacement, const GridMaps& maps,
                                             const VoxelLattice& lattice, std::size_t voxels, const std::string& meshName)
{
  const MeshNodes nodes = meshNodesOf(mesh, displacement, maps, meshName);
  VoxelCorrection result;
  result.w.assign(3 * voxels, 0.0f);
  result.located.assign(voxels, 0);
  forEachTetrahedron(mesh, meshName, [&](vtkIdType, const vtkIdType v[4]) { rasteriseDeformedTetrahedron(v, nodes, displacement, lattice, result); });
  return result;
}

double largestCorrectionInMesh(const VoxelCorrection& correction)
{
  const std::vector<float>& w = correction.w;
  double largest = 0;
  for (std::size_t i = 0; i < correction.located.size(); ++i) {
    if (!correction.located[i]) continue;
    const double w2 = double(w[3 * i]) * w[3 * i] + double(w[3 * i + 1]) * w[3 * i + 1] + double(w[3 * i + 2]) * w[3 * i + 2];
    largest = std::max(largest, std::sqrt(w2));
  }
  return largest;
}

/// The grid the fade is smoothed on: the intraoperative grid coarser by whole factors (blocks of
/// voxels, spacing up to sigma / 2), each coarse voxel at its block's centre.
struct CoarseBlocks {
  long factor[3], coarse[3];
  ImageGeometry grid;
  std::size_t blockOf(long i, long j, long k) const
  {
    return std::size_t(i / factor[0] + coarse[0] * (j / factor[1] + coarse[1] * (k / factor[2])));
  }
};

CoarseBlocks coarseBlocksFor(const ImageGeometry& grid, const VoxelLattice& lattice, double sigma)
{
  CoarseBlocks blocks;
  blocks.grid = grid;
  const long full[3] = {lattice.nx, lattice.ny, lattice.nz};
  itk::ContinuousIndex<double, 3> firstBlockCentre;
  for (int d = 0; d < 3; ++d) {
    long& factor = blocks.factor[d];
    factor = std::max(1L, long(std::floor(sigma / (2.0 * grid.spacing[unsigned(d)]))));
    factor = std::max(1L, std::min(factor, full[d] / 4)); // the recursive Gaussian needs 4 voxels
    blocks.coarse[d] = (full[d] + factor - 1) / factor;
    blocks.grid.size[unsigned(d)] = std::size_t(blocks.coarse[d]);
    blocks.grid.spacing[unsigned(d)] = grid.spacing[unsigned(d)] * double(factor);
    firstBlockCentre[unsigned(d)] = 0.5 * double(factor - 1);
  }
  for (unsigned r = 0; r < 3; ++r) { // origin + direction (spacing * index)
    blocks.grid.origin[r] = grid.origin[r];
    for (unsigned c = 0; c < 3; ++c) blocks.grid.origin[r] += grid.direction[r][c] * grid.spacing[c] * firstBlockCentre[c];
  }
  return blocks;
}

/// The four channels of the fade, block means smoothed by the Gaussian of width `sigma`: channel 0
/// the mask m of the located voxels, 1 to 3 the correction times the mask, w m.
std::array<ScalarImage::Pointer, 4> smoothedMaskAndCorrection(const VoxelCorrection& correction, const VoxelLattice& lattice,
                                                              const CoarseBlocks& blocks, double sigma)
{
  const std::size_t coarseVoxels = blocks.grid.numberOfVoxels();
  std::array<ScalarImage::Pointer, 4> channels;
  for (auto& c : channels) {
    c = blocks.grid.allocate<ScalarImage>();
    c->FillBuffer(0.0f);
  }
  std::vector<float> blockCount(coarseVoxels, 0.0f);
  for (long k = 0; k < lattice.nz; ++k) {
    for (long j = 0; j < lattice.ny; ++j) {
      for (long i = 0; i < lattice.nx; ++i) {
        const std::size_t at = lattice.offset(i, j, k);
        const std::size_t block = blocks.blockOf(i, j, k);
        blockCount[block] += 1.0f;
        if (!correction.located[at]) continue;
        channels[0]->GetBufferPointer()[block] += 1.0f;
        for (int d = 0; d < 3; ++d) channels[std::size_t(d + 1)]->GetBufferPointer()[block] += correction.w[3 * at + std::size_t(d)];
      }
    }
  }
  std::array<ScalarImage::Pointer, 4> smoothed;
  for (std::size_t c = 0; c < 4; ++c) {
    float* v = channels[c]->GetBufferPointer();
    for (std::size_t b = 0; b < coarseVoxels; ++b) v[b] /= blockCount[b];
    smoothed[c] = gaussian(channels[c], sigma);
  }
  return smoothed;
}

/// The four smoothed channels at voxel (i, j, k) of the full grid: trilinear weights on the coarse
/// grid (clamped at its border).
std::array<double, 4> interpolateChannels(const std::array<const float*, 4>& smoothed, const CoarseBlocks& blocks, long i,
                                          long j, long k)
{
  const long index[3] = {i, j, k};
  long lo[3];
  double t[3];
  for (int d = 0; d < 3; ++d) {
    const long factor = blocks.factor[d], coarse = blocks.coarse[d];
    const double c = std::clamp((double(index[d]) - 0.5 * double(factor - 1)) / double(factor), 0.0, double(coarse - 1));
    lo[d] = std::min(long(c), coarse - 2 >= 0 ? coarse - 2 : 0);
    t[d] = c - double(lo[d]);
  }
  std::array<double, 4> value{0, 0, 0, 0};
  for (int corner = 0; corner < 8; ++corner) {
    double weight = 1;
    long q[3];
    for (int d = 0; d < 3; ++d) {
      const int up = (corner >> d) & 1;
      q[d] = std::min(lo[d] + up, blocks.coarse[d] - 1);
      weight *= up ? t[d] : 1.0 - t[d];
    }
    if (weight == 0) continue;
    const std::size_t b = std::size_t(q[0] + blocks.coarse[0] * (q[1] + blocks.coarse[1] * q[2]));
    for (std::size_t c = 0; c < 4; ++c) value[c] += weight * double(smoothed[c][b]);
  }
  return value;
}

/// Outside the mesh the correction fades out, w = G*(w m) / G*m * min(1, 2 G*m). The smoothed
/// fields vary on the scale of sigma, so they are computed on a coarser grid and interpolated
/// trilinearly: a sixth to a hundredth of the voxels to smooth. Returns sigma, the fade's width.
double fadeCorrectionOutsideMesh(VoxelCorrection& correction, const ImageGeometry& grid, const VoxelLattice& lattice,
                                 double minimumSigmaMm)
{
  const double sigma = std::max(minimumSigmaMm, 1.2 * largestCorrectionInMesh(correction));
  const CoarseBlocks blocks = coarseBlocksFor(grid, lattice, sigma);
  const std::array<ScalarImage::Pointer, 4> smoothedImages = smoothedMaskAndCorrection(correction, lattice, blocks, sigma);
  std::array<const float*, 4> smoothed{};
  for (std::size_t c = 0; c < 4; ++c) smoothed[c] = smoothedImages[c]->GetBufferPointer();
  parallelRanges(std::size_t(lattice.nz), [&](std::size_t kBegin, std::size_t kEnd, unsigned) {
    for (long k = long(kBegin); k < long(kEnd); ++k) {
      for (long j = 0; j < lattice.ny; ++j) {
        for (long i = 0; i < lattice.nx; ++i) {
          const std::size_t at = lattice.offset(i, j, k);
          if (correction.located[at]) continue;
          const std::array<double, 4> value = interpolateChannels(smoothed, blocks, i, j, k);
          const double m = value[0];
          for (int d = 0; d < 3; ++d) {
            correction.w[3 * at + std::size_t(d)] = m > 1e-6 ? float(value[d + 1] / m * std::min(1.0, 2.0 * m)) : 0.0f;
          }
        }
      }
    }
  });
  return sigma;
}

/// The correction continued outside the mesh: each voxel of the band, its nearer neighbours' mean.
struct Continuation {
  std::vector<std::size_t> voxels; ///< in the order reached (nearest first)
  std::vector<float> w;            ///< three a voxel
  std::vector<float> distanceMm;   ///< along the grid's axes from the mesh
};

/// Grows the band outward from the located voxels in order of distance from the mesh (in mm along
/// the grid's axes, over face neighbours), to `reachMm`: a voxel reached takes the mean correction
/// of its neighbours nearer the mesh (the mesh's, or the band's), each weighted by the inverse
/// square of its step. In order of distance, not of steps: on thick slices a step across them is
/// 2.5 mm against 0.94 in plane, and a column counted in steps took its correction from the mesh
/// below it, 15 mm away, over the one 5 mm away in its own slice (a pillar of the deep brain's 4 mm
/// in the gap above a 16 mm sink, preoperative brain shown in it: the 20 mm scenarios).
Continuation continueCorrection(const VoxelCorrection& correction, const VoxelLattice& lattice, const ImageGeometry& grid,
                                double reachMm)
{
  const std::size_t n = correction.located.size();
  if (n >= std::size_t(std::numeric_limits<std::uint32_t>::max())) {
    throw std::invalid_argument("warp: " + std::to_string(n) + " voxels on the intraoperative grid; the correction's continuation takes fewer than 2^32");
  }
  // The band is taken shell by shell, each as thick as the shortest step: a voxel offered from a
  // shell goes into a later one (whatever its distance rounds to: float(0.7) < 0.7), and its mean
  // reads the voxels of earlier shells alone (Done), never its own shell's (InShell).
  const double shellMm = std::min({grid.spacing[0], grid.spacing[1], grid.spacing[2]});
  std::vector<float> distance(n, std::numeric_limits<float>::infinity());
  // Each band voxel's place in band.w, set when its shell is done (read only for done voxels):
  // 4 bytes a voxel, uninitialised, where a dense copy of the corrections took 12, zeroed.
  const std::unique_ptr<std::uint32_t[]> slot(new std::uint32_t[n]);
  enum : unsigned char { Unreached = 0, Reached = 1, InShell = 2, Done = 3 };
  std::vector<unsigned char> state(n, Unreached);
  const long steps[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  auto forNeighbours = [&](std::size_t at, auto&& visit) {
    const long i = long(at % std::size_t(lattice.nx)), j = long((at / std::size_t(lattice.nx)) % std::size_t(lattice.ny)),
               k = long(at / std::size_t(lattice.nx * lattice.ny));
    for (int s = 0; s < 6; ++s) {
      const long a = i + steps[s][0], b = j + steps[s][1], c = k + steps[s][2];
      if (a < 0 || b < 0 || c < 0 || a >= lattice.nx || b >= lattice.ny || c >= lattice.nz) continue;
      visit(lattice.offset(a, b, c), grid.spacing[unsigned(s / 2)]);
    }
  };
  std::vector<std::vector<std::uint32_t>> shell(std::size_t(reachMm / shellMm) + 2);
  std::size_t current = 0; // the shell being taken; the mesh is shell 0
  auto offer = [&](std::size_t nb, double throughMm) { // a path to nb this long
    if (state[nb] >= InShell || throughMm > reachMm || float(throughMm) >= distance[nb]) return;
    distance[nb] = float(throughMm);
    state[nb] = Reached;
    const std::size_t into = std::max(current + 1, std::size_t(double(distance[nb]) / shellMm));
    if (into >= shell.size()) shell.resize(into + 1);
    shell[into].push_back(std::uint32_t(nb));
  };
  for (std::size_t at = 0; at < n; ++at) {
    if (!correction.located[at]) continue;
    state[at] = Done;
    distance[at] = 0.0f;
  }
  for (std::size_t at = 0; at < n; ++at) {
    if (correction.located[at]) forNeighbours(at, [&](std::size_t nb, double step) { offer(nb, step); });
  }
  Continuation band;
  for (current = 1; current < shell.size(); ++current) {
    const std::size_t first = band.voxels.size();
    for (std::uint32_t at : shell[current]) { // once each: a voxel offered again nearer sits in an earlier shell too
      if (state[at] != Reached) continue;
      state[at] = InShell;
      band.voxels.push_back(at);
      band.distanceMm.push_back(distance[at]);
    }
    std::vector<std::uint32_t>().swap(shell[current]);
    for (std::size_t b = first; b < band.voxels.size(); ++b) {
      double sum[3] = {0, 0, 0}, weights = 0;
      forNeighbours(band.voxels[b], [&](std::size_t nb, double step) {
        if (state[nb] != Done) return;
        const float* w = correction.located[nb] ? &correction.w[3 * nb] : &band.w[3 * std::size_t(slot[nb])];
        const double weight = 1.0 / (step * step);
        for (int d = 0; d < 3; ++d) sum[d] += weight * w[d];
        weights += weight;
      });
      // Offered by a Done neighbour, so weights > 0.
      for (int d = 0; d < 3; ++d) band.w.push_back(float(sum[d] / weights));
    }
    for (std::size_t b = first; b < band.voxels.size(); ++b) {
      const std::size_t at = band.voxels[b];
      slot[at] = std::uint32_t(b);
      state[at] = Done;
    }
    for (std::size_t b = first; b < band.voxels.size(); ++b) {
      const std::size_t at = band.voxels[b];
      forNeighbours(at, [&](std::size_t nb, double step) { offer(nb, double(distance[at]) + step); });
    }
  }
  return band;
}

/// Keeps the continued correction whole over the first layer of voxels outside the mesh (within
/// the grid's largest spacing: a thick slice whose centre lies outside the deformed mesh still
/// holds its boundary), then blends it into the fade (already in correction.w) over the band, and
/// returns the band's width: wide enough that the blend compresses the space across it by at most
/// the parameters' share (the largest difference between the two anywhere within reach, over that
/// share), within their bounds.
double blendContinuation(VoxelCorrection& correction, const Continuation& band, const ImageGeometry& grid,
                         const DeformationFieldParameters& parameters, std::size_t& continuedVoxels)
{
  const double firstLayerMm = std::max({grid.spacing[0], grid.spacing[1], grid.spacing[2]});
  double largestJump = 0;
  for (std::size_t b = 0; b < band.voxels.size(); ++b) {
    const float* fade = &correction.w[3 * band.voxels[b]];
    double squared = 0;
    for (int d = 0; d < 3; ++d) squared += std::pow(double(band.w[3 * b + std::size_t(d)]) - fade[d], 2);
    largestJump = std::max(largestJump, std::sqrt(squared));
  }
  const double width = std::clamp(largestJump / parameters.continuationMaximumCompression, parameters.continuationMinimumMm,
                                  parameters.continuationMaximumMm);
  continuedVoxels = 0;
  for (std::size_t b = 0; b < band.voxels.size(); ++b) {
    const double t = std::max(0.0, band.distanceMm[b] - firstLayerMm) / width;
    if (t >= 1) continue;
    float* w = &correction.w[3 * band.voxels[b]];
    for (int d = 0; d < 3; ++d) w[d] = float((1 - t) * band.w[3 * b + std::size_t(d)] + t * w[d]);
    ++continuedVoxels;
  }
  return width;
}

/// The whole mapping: x = R(y) + w, d = x - y; also the largest |w|.
DisplacementFieldImage::Pointer rigidWithCorrectionField(const VoxelCorrection& correction, const GridMaps& maps,
                                                         const ImageGeometry& grid, double& maximumNonRigidMm)
{
  const VoxelLattice lattice(grid);
  DisplacementFieldImage::Pointer result = grid.allocate<DisplacementFieldImage>();
  DisplacementVector* field = result->GetBufferPointer();
  const std::vector<float>& correctionW = correction.w;
  std::vector<double> largest(parallelThreads(), 0.0);
  parallelRanges(std::size_t(lattice.nz), [&](std::size_t kBegin, std::size_t kEnd, unsigned thread) {
    double threadLargest = 0; // kept local: the threads' slots share a cache line
    for (long k = long(kBegin); k < long(kEnd); ++k) {
      for (long j = 0; j < lattice.ny; ++j) {
        for (long i = 0; i < lattice.nx; ++i) {
          const std::size_t at = lattice.offset(i, j, k);
          const Vec y = maps.indexToPhysical * Vec(double(i), double(j), double(k)) + maps.origin;
          const Vec w(correctionW[3 * at], correctionW[3 * at + 1], correctionW[3 * at + 2]);
          threadLargest = std::max(threadLargest, w.norm());
          const Vec x = maps.rigidMatrix * y + maps.rigidTranslation + w;
          for (int d = 0; d < 3; ++d) field[at][unsigned(d)] = float(x[d] - y[d]);
        }
      }
    }
    largest[thread] = threadLargest;
  });
  maximumNonRigidMm = std::max(maximumNonRigidMm, *std::max_element(largest.begin(), largest.end()));
  return result;
}

/// Folding: det of the Jacobian of y -> x (central differences in index space, one-sided at the
/// border, then physical) into result.jacobianDeterminant, with its minimum and the folded voxels,
/// all and those inside the deformed mesh (`located` 1).
void measureFolding(const GridMaps& maps, const ImageGeometry& grid, const std::vector<unsigned char>& located, DeformationField& result)
{
  const long nx = long(grid.size[0]), ny = long(grid.size[1]), nz = long(grid.size[2]);
  const DisplacementVector* field = result.field->GetBufferPointer();
  result.jacobianDeterminant = grid.allocate<ScalarImage>();
  float* jacobian = result.jacobianDeterminant->GetBufferPointer();
  const Mat physicalToIndex = maps.indexToPhysical.inverse();
  std::vector<double> minimum(parallelThreads(), std::numeric_limits<double>::infinity());
  std::vector<std::size_t> folded(parallelThreads(), 0), foldedInMesh(parallelThreads(), 0);
  parallelRanges(std::size_t(nz), [&](std::size_t kBegin, std::size_t kEnd, unsigned thread) {
    double threadMinimum = std::numeric_limits<double>::infinity(); // kept local: the threads' slots share a cache line
    std::size_t threadFolded = 0, threadFoldedInMesh = 0;
    for (long k = long(kBegin); k < long(kEnd); ++k) {
      for (long j = 0; j < ny; ++j) {
        for (long i = 0; i < nx; ++i) {
          const long idx[3] = {i, j, k};
          const long size[3] = {nx, ny, nz};
          Mat dIndex; // d(d)/d(index)
          for (int a = 0; a < 3; ++a) {
            long lo[3] = {i, j, k}, hi[3] = {i, j, k};
            lo[a] = std::max(0L, idx[a] - 1);
            hi[a] = std::min(size[a] - 1, idx[a] + 1);
            const double step = double(hi[a] - lo[a]);
            const DisplacementVector& f1 = field[std::size_t(hi[0] + nx * (hi[1] + ny * hi[2]))];
            const DisplacementVector& f0 = field[std::size_t(lo[0] + nx * (lo[1] + ny * lo[2]))];
            for (int d = 0; d < 3; ++d) dIndex(d, a) = step > 0 ? (double(f1[unsigned(d)]) - double(f0[unsigned(d)])) / step : 0.0;
          }
          const double det = (Mat::Identity() + dIndex * physicalToIndex).determinant();
          const std::size_t at = std::size_t(i + nx * (j + ny * k));
          jacobian[at] = float(det);
          threadMinimum = std::min(threadMinimum, det);
          threadFolded += det <= 0;
          threadFoldedInMesh += det <= 0 && located[at] == 1;
        }
      }
    }
    minimum[thread] = threadMinimum;
    folded[thread] = threadFolded;
    foldedInMesh[thread] = threadFoldedInMesh;
  });
  result.minimumJacobian = *std::min_element(minimum.begin(), minimum.end());
  result.foldedVoxels = std::accumulate(folded.begin(), folded.end(), std::size_t(0));
  result.foldedVoxelsInMesh = std::accumulate(foldedInMesh.begin(), foldedInMesh.end(), std::size_t(0));
}
} // namespace

DeformationField intraopToPreopField(vtkUnstructuredGrid* mesh, const SpatialTransform& rigid, const ImageGeometry& grid,
                                     const DeformationFieldParameters& parameters, const std::string& meshName)
{
  vtkDataArray* displacement = mesh->GetPointData()->GetArray("Displacement");
  checkFieldInputs(displacement, rigid, parameters, meshName);
  DeformationField result;
  const GridMaps maps = gridMapsOf(rigid, grid);
  const VoxelLattice lattice(grid);
  result.voxels = grid.numberOfVoxels();

  const auto locateStart = std::chrono::steady_clock::now();
  VoxelCorrection correction = correctionInsideDeformedMesh(mesh, displacement, maps, lattice, result.voxels, meshName);
  result.invertedDeformedTetrahedra = correction.invertedDeformedTetrahedra;
  result.locateSeconds = secondsSince(locateStart);

  const auto fallbackStart = std::chrono::steady_clock::now();
  result.meshVoxels = std::size_t(std::count(correction.located.begin(), correction.located.end(), 1));
  // The continuation (layer by layer, on one core) beside the fade (on the others): it reads the
  // mesh's voxels alone, the fade writes the others alone; the blend takes both.
  std::future<Continuation> continued = std::async(std::launch::async, [&] {
    return parameters.continuationMaximumMm > 0 ? continueCorrection(correction, lattice, grid, parameters.continuationMaximumMm)
                                                : Continuation{};
  });
  try {
    result.fallbackSigmaMm = fadeCorrectionOutsideMesh(correction, grid, lattice, parameters.fallbackSigmaMm);
  } catch (...) {
    continued.wait(); // its references must outlive it
    throw;
  }
  const Continuation band = continued.get();
  if (!band.voxels.empty()) result.continuationBandMm = blendContinuation(correction, band, grid, parameters, result.continuedVoxels);
  result.fallbackSeconds = secondsSince(fallbackStart);

  result.field = rigidWithCorrectionField(correction, maps, grid, result.maximumNonRigidMm);

  const auto jacobianStart = std::chrono::steady_clock::now();
  measureFolding(maps, grid, correction.located, result);
  result.jacobianSeconds = secondsSince(jacobianStart);
  return result;
}

MaskImage::Pointer voxelsOfDeformedTissue(vtkUnstructuredGrid* mesh, LabelPixel label, const SpatialTransform& rigidIntraopToPreop,
                                          const ImageGeometry& grid, const std::string& meshName)
{
  vtkDataArray* displacement = mesh->GetPointData()->GetArray("Displacement");
  requireSolvedMeshAndLinearRigid(displacement, rigidIntraopToPreop, meshName);
  vtkDataArray* labels = mesh->GetCellData()->GetArray("Label");
  if (!labels) throw InputError(meshName + ": no cell array \"Label\"");
  const GridMaps maps = gridMapsOf(rigidIntraopToPreop, grid);
  const VoxelLattice lattice(grid);
  const MeshNodes nodes = meshNodesOf(mesh, displacement, maps, meshName);
  MaskImage::Pointer mask = grid.allocate<MaskImage>();
  unsigned char* m = mask->GetBufferPointer();
  std::fill_n(m, grid.numberOfVoxels(), 0);
  forEachTetrahedron(mesh, meshName, [&](vtkIdType c, const vtkIdType v[4]) {
    if (std::lround(labels->GetComponent(c, 0)) != long(label)) return;
    forEachVoxelInTetrahedron(
      deformedCorners(v, nodes), lattice, [&](std::size_t at) { return m[at] != 0; },
      [&](std::size_t at, const std::array<double, 4>&) { m[at] = 1; });
  });
  return mask;
}

DisplacementFieldImage::Pointer linearTransformField(const SpatialTransform& transform, const ImageGeometry& grid)
{
  if (!isLinearTransform(&transform)) {
    throw InputError("linearTransformField: " + describeTransform(&transform) + " is not a linear transform");
  }
  const GridMaps g = gridMapsOf(transform, grid);
  DisplacementFieldImage::Pointer field = grid.allocate<DisplacementFieldImage>();
  DisplacementVector* out = field->GetBufferPointer();
  const long nx = long(grid.size[0]), ny = long(grid.size[1]), nz = long(grid.size[2]);
  parallelRanges(std::size_t(nz), [&](std::size_t kBegin, std::size_t kEnd, unsigned) {
    for (long k = long(kBegin); k < long(kEnd); ++k) {
      for (long j = 0; j < ny; ++j) {
        for (long i = 0; i < nx; ++i) {
          const Vec y = g.indexToPhysical * Vec(double(i), double(j), double(k)) + g.origin;
          const Vec d = g.rigidMatrix * y + g.rigidTranslation - y;
          DisplacementVector& v = out[std::size_t(i + nx * (j + ny * k))];
          for (unsigned c = 0; c < 3; ++c) v[c] = float(d[int(c)]);
        }
      }
    }
  });
  return field;
}

namespace {
/// `values` (x fastest) as an image on `field`'s grid.
template <class TImage>
typename TImage::Pointer imageOnFieldGrid(const std::vector<typename TImage::PixelType>& values, const DisplacementFieldImage& field)
{
  typename TImage::Pointer image = ImageGeometry::of(&field).allocate<TImage>();
  std::copy(values.begin(), values.end(), image->GetBufferPointer());
  return image;
}
} // namespace

ScalarImage::Pointer warpScalarVolume(const ScalarImage& moving, const DisplacementFieldImage& field)
{
  return imageOnFieldGrid<ScalarImage>(linearlyWarped(moving, field), field);
}

LabelImage::Pointer warpLabelVolume(const LabelImage& moving, const DisplacementFieldImage& field)
{
  return imageOnFieldGrid<LabelImage>(nearestWarped(moving, field), field);
}

} // namespace brainshift
