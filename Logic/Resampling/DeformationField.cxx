#include "DeformationField.h"

#include <itkLinearInterpolateImageFunction.h>
#include <itkNearestNeighborInterpolateImageFunction.h>
#include <itkSmoothingRecursiveGaussianImageFilter.h>
#include <itkWarpImageFilter.h>

// ITK brings its own Eigen; a second copy in the same translation unit clashes.
#include <itk_eigen.h>
#include ITK_EIGEN(Dense)

#include <vtkCellArray.h>
#include <vtkDataArray.h>
#include <vtkIdList.h>
#include <vtkPointData.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>

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
} // namespace

DeformationField intraopToPreopField(vtkUnstructuredGrid* mesh, const SpatialTransform& rigid, const ImageGeometry& grid,
                                     const DeformationFieldParameters& parameters, const std::string& meshName)
{
  vtkDataArray* displacement = mesh->GetPointData()->GetArray("Displacement");
  if (!displacement || displacement->GetNumberOfComponents() != 3) {
    throw InputError(meshName + ": no point array \"Displacement\"; run `brainshift simulate` on this output folder first");
  }
  if (!isLinearTransform(&rigid)) throw InputError("the rigid transform is not linear");
  if (!(parameters.fallbackSigmaMm > 0) || parameters.fallbackSigmaMm > 100) {
    throw InputError("warp: the fallback width must be within 0 to 100 mm");
  }
  DeformationField result;
  const GridMaps maps = gridMapsOf(rigid, grid);
  const long nx = long(grid.size[0]), ny = long(grid.size[1]), nz = long(grid.size[2]);
  const std::size_t voxels = grid.numberOfVoxels();
  result.voxels = voxels;

  // -- Locate every voxel's model-frame point in the deformed mesh: rasterise each deformed
  //    tetrahedron over the voxels of its box (index space is an affine image of the model frame,
  //    so barycentric coordinates carry over).
  const auto locateStart = std::chrono::steady_clock::now();
  const vtkIdType nodes = mesh->GetNumberOfPoints();
  const std::size_t nodeCount = std::size_t(nodes);
  std::vector<Vec> undeformed(nodeCount), deformedIndex(nodeCount);
  for (vtkIdType i = 0; i < nodes; ++i) {
    Vec x, u;
    mesh->GetPoint(i, x.data());
    displacement->GetTuple(i, u.data());
    if (!u.allFinite()) throw InputError(meshName + ": the displacement of node " + std::to_string(i) + " is not finite");
    undeformed[std::size_t(i)] = x;
    deformedIndex[std::size_t(i)] = maps.modelToIndex * (x + u) + maps.modelToIndexOffset;
  }
  std::vector<float> correction(3 * voxels, 0.0f); // X - p, model frame
  std::vector<unsigned char> located(voxels, 0);
  vtkNew<vtkIdList> ids;
  for (vtkIdType c = 0; c < mesh->GetNumberOfCells(); ++c) {
    mesh->GetCellPoints(c, ids);
    if (ids->GetNumberOfIds() != 4) throw InputError(meshName + ": cell " + std::to_string(c) + " is not a tetrahedron");
    const vtkIdType v[4] = {ids->GetId(0), ids->GetId(1), ids->GetId(2), ids->GetId(3)};
    const Vec& q0 = deformedIndex[std::size_t(v[0])];
    Mat edges;
    edges.col(0) = deformedIndex[std::size_t(v[1])] - q0;
    edges.col(1) = deformedIndex[std::size_t(v[2])] - q0;
    edges.col(2) = deformedIndex[std::size_t(v[3])] - q0;
    const double det = edges.determinant();
    const Mat undeformedEdges = [&] {
      Mat m;
      for (int k = 0; k < 3; ++k) m.col(k) = undeformed[std::size_t(v[k + 1])] - undeformed[std::size_t(v[0])];
      return m;
    }();
    if (det * undeformedEdges.determinant() <= 0) ++result.invertedDeformedTetrahedra;
    if (std::abs(det) < 1e-12) continue;
    const Mat inverse = edges.inverse();
    Vec lo = q0, hi = q0;
    for (int k = 1; k < 4; ++k) {
      lo = lo.cwiseMin(deformedIndex[std::size_t(v[k])]);
      hi = hi.cwiseMax(deformedIndex[std::size_t(v[k])]);
    }
    const long i0 = std::max(0L, long(std::ceil(lo[0]))), i1 = std::min(nx - 1, long(std::floor(hi[0])));
    const long j0 = std::max(0L, long(std::ceil(lo[1]))), j1 = std::min(ny - 1, long(std::floor(hi[1])));
    const long k0 = std::max(0L, long(std::ceil(lo[2]))), k1 = std::min(nz - 1, long(std::floor(hi[2])));
    for (long k = k0; k <= k1; ++k) {
      for (long j = j0; j <= j1; ++j) {
        for (long i = i0; i <= i1; ++i) {
          const std::size_t at = std::size_t(i + nx * (j + ny * k));
          if (located[at]) continue;
          const Vec lambda = inverse * (Vec(double(i), double(j), double(k)) - q0);
          const double lambda0 = 1.0 - lambda.sum();
          const double eps = -1e-9;
          if (lambda[0] < eps || lambda[1] < eps || lambda[2] < eps || lambda0 < eps) continue;
          located[at] = 1;
          // X - p = -(sum lambda_k u_k): the preoperative point minus the deformed one.
          Vec u0, u1, u2, u3;
          displacement->GetTuple(v[0], u0.data());
          displacement->GetTuple(v[1], u1.data());
          displacement->GetTuple(v[2], u2.data());
          displacement->GetTuple(v[3], u3.data());
          const Vec w = -(lambda0 * u0 + lambda[0] * u1 + lambda[1] * u2 + lambda[2] * u3);
          for (int d = 0; d < 3; ++d) correction[3 * at + std::size_t(d)] = float(w[d]);
        }
      }
    }
  }
  result.locateSeconds = secondsSince(locateStart);

  // -- Outside the mesh: the correction fades out, w = G*(w m) / G*m * min(1, 2 G*m). The
  //    smoothed fields vary on the scale of sigma, so they are computed on a grid coarser by whole
  //    factors (block means, spacing up to sigma / 2) and interpolated trilinearly: a sixth to a
  //    hundredth of the voxels to smooth.
  const auto fallbackStart = std::chrono::steady_clock::now();
  result.meshVoxels = std::size_t(std::count(located.begin(), located.end(), 1));
  double largestCorrection = 0;
  for (std::size_t i = 0; i < voxels; ++i) {
    if (!located[i]) continue;
    const double w2 = double(correction[3 * i]) * correction[3 * i] + double(correction[3 * i + 1]) * correction[3 * i + 1] +
                      double(correction[3 * i + 2]) * correction[3 * i + 2];
    largestCorrection = std::max(largestCorrection, std::sqrt(w2));
  }
  const double sigma = std::max(parameters.fallbackSigmaMm, 1.2 * largestCorrection);
  result.fallbackSigmaMm = sigma;
  const long full[3] = {nx, ny, nz};
  long factor[3], coarse[3];
  ImageGeometry coarseGrid = grid;
  itk::ContinuousIndex<double, 3> firstBlockCentre;
  for (int d = 0; d < 3; ++d) {
    factor[d] = std::max(1L, long(std::floor(sigma / (2.0 * grid.spacing[unsigned(d)]))));
    factor[d] = std::max(1L, std::min(factor[d], full[d] / 4)); // the recursive Gaussian needs 4 voxels
    coarse[d] = (full[d] + factor[d] - 1) / factor[d];
    coarseGrid.size[unsigned(d)] = std::size_t(coarse[d]);
    coarseGrid.spacing[unsigned(d)] = grid.spacing[unsigned(d)] * double(factor[d]);
    firstBlockCentre[unsigned(d)] = 0.5 * double(factor[d] - 1);
  }
  for (unsigned r = 0; r < 3; ++r) { // origin + direction (spacing * index)
    coarseGrid.origin[r] = grid.origin[r];
    for (unsigned c = 0; c < 3; ++c) coarseGrid.origin[r] += grid.direction[r][c] * grid.spacing[c] * firstBlockCentre[c];
  }
  const std::size_t coarseVoxels = coarseGrid.numberOfVoxels();
  // Channel 0: the mask m; 1 to 3: w m. Block means.
  std::array<ScalarImage::Pointer, 4> channels;
  for (auto& c : channels) {
    c = coarseGrid.allocate<ScalarImage>();
    c->FillBuffer(0.0f);
  }
  std::vector<float> blockCount(coarseVoxels, 0.0f);
  for (long k = 0; k < nz; ++k) {
    for (long j = 0; j < ny; ++j) {
      for (long i = 0; i < nx; ++i) {
        const std::size_t at = std::size_t(i + nx * (j + ny * k));
        const std::size_t block = std::size_t(i / factor[0] + coarse[0] * (j / factor[1] + coarse[1] * (k / factor[2])));
        blockCount[block] += 1.0f;
        if (!located[at]) continue;
        channels[0]->GetBufferPointer()[block] += 1.0f;
        for (int d = 0; d < 3; ++d) channels[std::size_t(d + 1)]->GetBufferPointer()[block] += correction[3 * at + std::size_t(d)];
      }
    }
  }
  std::array<const float*, 4> smoothed{};
  std::array<ScalarImage::Pointer, 4> smoothedImages;
  for (std::size_t c = 0; c < 4; ++c) {
    float* v = channels[c]->GetBufferPointer();
    for (std::size_t b = 0; b < coarseVoxels; ++b) v[b] /= blockCount[b];
    smoothedImages[c] = gaussian(channels[c], sigma);
    smoothed[c] = smoothedImages[c]->GetBufferPointer();
  }
  for (long k = 0; k < nz; ++k) {
    for (long j = 0; j < ny; ++j) {
      for (long i = 0; i < nx; ++i) {
        const std::size_t at = std::size_t(i + nx * (j + ny * k));
        if (located[at]) continue;
        // Trilinear weights on the coarse grid (clamped at its border).
        const long index[3] = {i, j, k};
        long lo[3];
        double t[3];
        for (int d = 0; d < 3; ++d) {
          const double c = std::clamp((double(index[d]) - 0.5 * double(factor[d] - 1)) / double(factor[d]), 0.0, double(coarse[d] - 1));
          lo[d] = std::min(long(c), coarse[d] - 2 >= 0 ? coarse[d] - 2 : 0);
          t[d] = c - double(lo[d]);
        }
        double value[4] = {0, 0, 0, 0};
        for (int corner = 0; corner < 8; ++corner) {
          double weight = 1;
          long q[3];
          for (int d = 0; d < 3; ++d) {
            const int up = (corner >> d) & 1;
            q[d] = std::min(lo[d] + up, coarse[d] - 1);
            weight *= up ? t[d] : 1.0 - t[d];
          }
          if (weight == 0) continue;
          const std::size_t b = std::size_t(q[0] + coarse[0] * (q[1] + coarse[1] * q[2]));
          for (std::size_t c = 0; c < 4; ++c) value[c] += weight * double(smoothed[c][b]);
        }
        const double m = value[0];
        for (int d = 0; d < 3; ++d) {
          correction[3 * at + std::size_t(d)] = m > 1e-6 ? float(value[d + 1] / m * std::min(1.0, 2.0 * m)) : 0.0f;
        }
      }
    }
  }
  result.fallbackSeconds = secondsSince(fallbackStart);

  // -- The whole mapping: x = R(y) + w, d = x - y.
  result.field = grid.allocate<DisplacementFieldImage>();
  DisplacementVector* field = result.field->GetBufferPointer();
  for (long k = 0; k < nz; ++k) {
    for (long j = 0; j < ny; ++j) {
      for (long i = 0; i < nx; ++i) {
        const std::size_t at = std::size_t(i + nx * (j + ny * k));
        const Vec y = maps.indexToPhysical * Vec(double(i), double(j), double(k)) + maps.origin;
        const Vec w(correction[3 * at], correction[3 * at + 1], correction[3 * at + 2]);
        result.maximumNonRigidMm = std::max(result.maximumNonRigidMm, w.norm());
        const Vec x = maps.rigidMatrix * y + maps.rigidTranslation + w;
        for (int d = 0; d < 3; ++d) field[at][unsigned(d)] = float(x[d] - y[d]);
      }
    }
  }

  // -- Folding: det of the Jacobian of y -> x (central differences in index space, then physical).
  const auto jacobianStart = std::chrono::steady_clock::now();
  result.jacobianDeterminant = grid.allocate<ScalarImage>();
  float* jacobian = result.jacobianDeterminant->GetBufferPointer();
  const Mat physicalToIndex = maps.indexToPhysical.inverse();
  result.minimumJacobian = std::numeric_limits<double>::infinity();
  for (long k = 0; k < nz; ++k) {
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
        result.minimumJacobian = std::min(result.minimumJacobian, det);
        result.foldedVoxels += det <= 0;
      }
    }
  }
  result.jacobianSeconds = secondsSince(jacobianStart);
  return result;
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
  for (long k = 0; k < nz; ++k) {
    for (long j = 0; j < ny; ++j) {
      for (long i = 0; i < nx; ++i) {
        const Vec y = g.indexToPhysical * Vec(double(i), double(j), double(k)) + g.origin;
        const Vec d = g.rigidMatrix * y + g.rigidTranslation - y;
        DisplacementVector& v = out[std::size_t(i + nx * (j + ny * k))];
        for (unsigned c = 0; c < 3; ++c) v[c] = float(d[int(c)]);
      }
    }
  }
  return field;
}

namespace {
template <class TImage, class TInterpolator>
typename TImage::Pointer warp(const TImage& moving, const DisplacementFieldImage& field)
{
  using Warper = itk::WarpImageFilter<TImage, TImage, DisplacementFieldImage>;
  auto warper = Warper::New();
  warper->SetInput(&moving);
  warper->SetDisplacementField(&field);
  warper->SetInterpolator(TInterpolator::New());
  warper->SetOutputParametersFromImage(&field);
  warper->SetEdgePaddingValue(0);
  warper->Update();
  typename TImage::Pointer out = warper->GetOutput();
  out->DisconnectPipeline();
  return out;
}
} // namespace

ScalarImage::Pointer warpScalarVolume(const ScalarImage& moving, const DisplacementFieldImage& field)
{
  return warp<ScalarImage, itk::LinearInterpolateImageFunction<ScalarImage, double>>(moving, field);
}

LabelImage::Pointer warpLabelVolume(const LabelImage& moving, const DisplacementFieldImage& field)
{
  return warp<LabelImage, itk::NearestNeighborInterpolateImageFunction<LabelImage, double>>(moving, field);
}

} // namespace brainshift
