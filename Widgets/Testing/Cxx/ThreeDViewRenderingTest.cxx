// The 3D view of a known displacement-coloured surface against a committed baseline (300x300),
// with VTK's image comparison (RenderingComparison.h). A view without the colouring must fail
// the same comparison, so the tolerance cannot hide a lost colour map.
#include "RenderingComparison.h"
#include "SyntheticData.h"
#include "ThreeDView.h"

#include <vtkScalarBarActor.h>

#include <QApplication>
#include <QSurfaceFormat>
#include <QTest>

int ThreeDViewRenderingTest(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  return brainshift::testing::runTest("ThreeDViewRenderingTest", [] {
    using namespace brainshift;
    ThreeDView view;
    view.resize(300, 300);
    view.show();
    BS_CHECK(QTest::qWaitForWindowExposed(&view));

    auto surface = ModelNode::create("brain surface", testing::makeTetrahedronSurface());
    ModelDisplay display;
    display.scalarVisibility = true;
    display.activeScalarName = "DisplacementMagnitude";
    surface->setDisplay(display);
    view.setModels({surface});
    BS_CHECK(view.scalarBar()->GetVisibility());
    BS_CHECK(std::string(view.scalarBar()->GetTitle()) == "Displacement (mm)");
    const auto rendered = testing::capture(view);
    const int* size = rendered->GetDimensions();
    BS_CHECK_MSG(size[0] == 300 && size[1] == 300, size[0] << "x" << size[1]);
    const auto expected = testing::baseline("ThreeDViewRenderingTest", "ThreeDViewDisplacement.png", rendered);
    const double error = testing::differencePerPixel(rendered, expected);
    std::cout << "difference from the baseline: " << error << " per pixel\n";
    BS_CHECK_MSG(error < testing::renderingTolerance, error);

    // Without the colouring, the same comparison fails clearly.
    display.scalarVisibility = false;
    surface->setDisplay(display);
    view.setModels({surface});
    BS_CHECK(!view.scalarBar()->GetVisibility());
    const double uncoloured = testing::differencePerPixel(testing::capture(view), expected);
    std::cout << "an uncoloured surface differs by " << uncoloured << " per pixel\n";
    BS_CHECK_MSG(uncoloured > 2 * testing::renderingTolerance, uncoloured); // clearly outside the tolerance
  });
}
