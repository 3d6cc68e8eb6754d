// A slab field of view (issue 20), on the small case: the intraoperative grid keeps the in-plane
// field and 15 axial slices of 5 mm; the craniotomy and the tumour lie inside it; every landmark is
// seen in it; about half the brain is, against all of it for the whole head; the name is checked.
#include "BrainShiftTestingSupport.h"
#include "CaseSimulationTestSupport.h"

#include <iostream>

namespace {
using namespace brainshift;

/// The slice index (continuous) of a preoperative point seen in the intraoperative scan.
double sliceOf(const SimulatedCase& c, const PhysicalPoint& preop)
{
  const auto toIntraop = c.rigidIntraopToPreop->GetInverseTransform();
  itk::ContinuousIndex<double, 3> index;
  c.intraopImage->TransformPhysicalPointToContinuousIndex(toIntraop->TransformPoint(preop), index);
  return index[2];
}
} // namespace

int CaseSimulationSlabTest(int, char*[])
{
  return brainshift::testing::runTest("CaseSimulationSlabTest", [] {
    CaseParameters p = caseScenario("rf10-slab").parameters;
    p.size = CaseSize::Small;
    BS_CHECK(p.fieldOfView == FieldOfView::Slab);
    const SimulatedCase slab = simulateCase(p);
    const auto size = slab.intraopImage->GetLargestPossibleRegion().GetSize();
    BS_CHECK_MSG(size[0] == 96 && size[1] == 96 && size[2] == 15, size);
    BS_CHECK_NEAR(slab.intraopImage->GetSpacing()[2], 5.0, 1e-9);
    const double craniotomy = sliceOf(slab, slab.figures.craniotomyCentre), tumour = sliceOf(slab, slab.figures.tumourCentre);
    std::cout << "slab: craniotomy at slice " << craniotomy << ", tumour at " << tumour << ", brain " << slab.figures.brainInFieldOfViewMl
              << " of " << slab.figures.brainVolumeMl << " ml inside, " << slab.landmarks.size() << " landmarks\n";
    BS_CHECK(craniotomy > 1.0 && craniotomy < 13.0 && tumour > 1.0 && tumour < 13.0);
    BS_CHECK(slab.landmarks.size() >= 30);
    for (const LandmarkPair& l : slab.landmarks) {
      itk::ContinuousIndex<double, 3> index;
      BS_CHECK_MSG(slab.intraopImage->TransformPhysicalPointToContinuousIndex(l.intraop, index) && index[2] >= 1.0 && index[2] <= 13.0,
                   l.name);
    }
    const double share = slab.figures.brainInFieldOfViewMl / slab.figures.brainVolumeMl;
    BS_CHECK_MSG(share > 0.3 && share < 0.7, share);
    // The whole head: the same case sees all of the brain.
    p.fieldOfView = FieldOfView::WholeHead;
    const SimulatedCase whole = simulateCase(p);
    BS_CHECK(whole.intraopImage->GetLargestPossibleRegion().GetSize()[2] == 30);
    BS_CHECK_MSG(whole.figures.brainInFieldOfViewMl > 0.97 * whole.figures.brainVolumeMl, whole.figures.brainInFieldOfViewMl);
    BS_CHECK(toString(FieldOfView::Slab) == "slab" && fieldOfViewFromString("whole-head") == FieldOfView::WholeHead);
    BS_CHECK_THROWS(fieldOfViewFromString("partial"), InputError, "whole-head, slab");
  });
}
