// The finite element truth on the full built-in case, for measurement: off by default (it takes about a
// minute). Set BRAINSHIFT_FE_TRUTH_CASE to a case folder written by `brainshift demo` (its case/ folder,
// with preop_labels.nii.gz and case.json) and optionally BRAINSHIFT_FE_TRUTH_ELEMENT_MM; it prints the
// figures and the difference of w from the kinematic subsidence model (BrainShiftCaseSimulator.cxx) over
// the preoperative brain, on the simulator's 4 mm grid.
#include "BrainShiftTestingSupport.h"
#include "FiniteElementTruth.h"
#include "VolumeIO.h"

#include <itkImageRegionConstIteratorWithIndex.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iostream>

namespace {
using namespace brainshift;
using Vec3 = std::array<double, 3>;

/// The kinematic model's w (BrainShiftCaseSimulator.cxx): sinking along the axis, Gaussian across, decaying with depth.
Vec3 kinematicW(const Vec3& p, const Vec3& centre, const Vec3& axis, double shift, double sigma, double decay)
{
  const Vec3 d{p[0] - centre[0], p[1] - centre[1], p[2] - centre[2]};
  const double along = d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2];
  const double r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2] - along * along;
  const double subsidence = shift * std::exp(-r2 / (2 * sigma * sigma));
  const double s = subsidence * std::exp(-std::max(-along - subsidence, 0.0) / decay);
  return {s * axis[0], s * axis[1], s * axis[2]};
}
} // namespace

int FiniteElementTruthCaseTest(int, char*[])
{
  return brainshift::testing::runTest("FiniteElementTruthCaseTest", [] {
    const char* folder = std::getenv("BRAINSHIFT_FE_TRUTH_CASE");
    if (!folder) {
      std::cout << "skipped: set BRAINSHIFT_FE_TRUTH_CASE to a built-in case folder to measure\n";
      return;
    }
    const std::filesystem::path caseFolder(folder);
    const LabelImage::Pointer labels = readLabelVolume(caseFolder / "preop_labels.nii.gz");
    nlohmann::json description;
    std::ifstream(caseFolder / "case.json") >> description;
    const auto& figuresJson = description.at("figures");
    FiniteElementTruthParameters P;
    P.craniotomyCentre = figuresJson.at("craniotomy_centre_lps").get<Vec3>();
    P.craniotomyAxis = figuresJson.at("craniotomy_axis_lps").get<Vec3>();
    P.shiftMm = description.at("parameters").at("shift_mm").get<double>();
    if (const char* size = std::getenv("BRAINSHIFT_FE_TRUTH_ELEMENT_MM")) P.elementSizeMm = std::atof(size);
    // The simulator's grid of w: 4 mm over the preoperative field of view.
    const auto size = labels->GetLargestPossibleRegion().GetSize();
    const auto spacing = labels->GetSpacing();
    using Field = itk::Image<itk::Vector<double, 3>, 3>;
    auto field = Field::New();
    Field::SizeType fieldSize;
    Field::SpacingType fieldSpacing;
    for (int d = 0; d < 3; ++d) fieldSize[d] = std::size_t(std::ceil(spacing[d] * double(size[d] - 1) / 4.0)) + 1, fieldSpacing[d] = 4.0;
    field->SetRegions(fieldSize);
    field->SetSpacing(fieldSpacing);
    field->SetOrigin(labels->GetOrigin());
    field->SetDirection(labels->GetDirection());
    field->Allocate();
    const FiniteElementTruthFigures f = solveFiniteElementTruth(*labels, *field, P);
    std::cout << "element size " << P.elementSizeMm << " mm: " << f.nodes << " nodes, " << f.elements << " C3D10 (" << f.droppedElements
              << " dropped, " << f.invertedElements << " inverted); " << f.slidingNodes << " sliding, " << f.fixedNodes << " fixed, "
              << f.loadedNodes << " loaded; mesh " << f.meshSeconds << " s; ccx " << f.ccxSeconds << " s, " << f.ccxPeakMemoryMb
              << " MB; field " << f.fieldSeconds << " s (" << f.newtonFallbacks << " Newton, " << f.unconvergedInversions
              << " unconverged); max |u| " << f.maxDisplacementMm << " mm\n";
    double sum = 0, worst = 0, sumFe = 0, sumKin = 0;
    std::size_t count = 0;
    itk::ImageRegionConstIteratorWithIndex<Field> it(field, field->GetLargestPossibleRegion());
    for (; !it.IsAtEnd(); ++it) {
      PhysicalPoint p;
      field->TransformIndexToPhysicalPoint(it.GetIndex(), p);
      LabelImage::IndexType index;
      if (!labels->TransformPhysicalPointToIndex(p, index) || labels->GetPixel(index) < 2) continue;
      const Vec3 k = kinematicW({p[0], p[1], p[2]}, P.craniotomyCentre, P.craniotomyAxis, P.shiftMm, 25.0, 35.0);
      const auto w = it.Get();
      const double difference = std::sqrt(std::pow(w[0] - k[0], 2) + std::pow(w[1] - k[1], 2) + std::pow(w[2] - k[2], 2));
      sum += difference, worst = std::max(worst, difference), ++count;
      sumFe += w.GetNorm(), sumKin += std::sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2]);
    }
    std::cout << count << " grid points in the preoperative brain: |w_fe - w_kinematic| mean " << sum / double(count) << " mm, max "
              << worst << " mm; mean |w_fe| " << sumFe / double(count) << " mm, mean |w_kinematic| " << sumKin / double(count) << " mm\n";
    BS_CHECK(f.unconvergedInversions == 0);
  });
}
