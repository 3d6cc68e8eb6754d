#pragma once
#include "BrainShiftCaseSimulator.h"
#include "LandmarkEvaluation.h"
#include "RigidRegistrationLogic.h"

#include <itkAffineTransform.h>
#include <itkVersorRigid3DTransform.h>

#include <array>
#include <cmath>

namespace brainshift::testing {

/// The small built-in case with the given head motion in the scanner.
inline SimulatedCase smallCaseWithMotion(std::array<double, 3> rotationDegrees, std::array<double, 3> translationMm)
{
  CaseParameters parameters;
  parameters.size = CaseSize::Small;
  parameters.rotationDegrees = rotationDegrees;
  parameters.translationMillimetres = translationMm;
  return simulateCase(parameters);
}

/// The error of a rigid result on the head landmarks, where only the rigid motion applies.
inline ErrorStatistics headError(const SpatialTransform& estimate, const SimulatedCase& c)
{
  return evaluateTransform(estimate, c.landmarks).groups.at("head");
}

/// The truth moved by a rotation of `degrees` about `axis` through the intraoperative image's centre and a
/// translation of `mm` along it: a pose known to be wrong by that much.
inline SpatialTransform::Pointer truthDisplaced(const SimulatedCase& c, std::array<double, 3> axis, double degrees, double mm)
{
  const double n = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
  auto displacement = itk::VersorRigid3DTransform<double>::New();
  const auto size = c.intraopImage->GetLargestPossibleRegion().GetSize();
  itk::ContinuousIndex<double, 3> middle;
  for (int i = 0; i < 3; ++i) middle[i] = 0.5 * (size[i] - 1);
  PhysicalPoint centre;
  c.intraopImage->TransformContinuousIndexToPhysicalPoint(middle, centre);
  displacement->SetCenter(centre);
  itk::Versor<double>::VectorType v;
  for (int i = 0; i < 3; ++i) v[i] = axis[i] / n;
  itk::Versor<double> versor;
  versor.Set(v, degrees * M_PI / 180.0);
  displacement->SetRotation(versor);
  itk::Versor<double>::VectorType shift = v * mm;
  displacement->SetTranslation(shift);
  auto wrong = itk::AffineTransform<double, 3>::New();
  const AffineParameters d = affineParametersOf(displacement.GetPointer());
  const AffineParameters t = affineParametersOf(c.rigidIntraopToPreop.GetPointer());
  itk::AffineTransform<double, 3>::MatrixType matrix;
  itk::AffineTransform<double, 3>::OutputVectorType offset;
  for (int r = 0; r < 3; ++r) {
    offset[r] = t.translation[r];
    for (int k = 0; k < 3; ++k) offset[r] += t.matrix[r][k] * d.translation[k];
    for (int col = 0; col < 3; ++col) {
      matrix(r, col) = 0;
      for (int k = 0; k < 3; ++k) matrix(r, col) += t.matrix[r][k] * d.matrix[k][col];
    }
  }
  wrong->SetMatrix(matrix);
  wrong->SetOffset(offset);
  return wrong.GetPointer();
}

} // namespace brainshift::testing
