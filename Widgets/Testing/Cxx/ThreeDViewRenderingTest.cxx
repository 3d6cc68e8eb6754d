// The 3D view of a known displacement-coloured surface against a committed baseline (300x300),
// with VTK's image comparison. A view without the colouring must fail the same comparison, so
// the tolerance cannot hide a lost colour map. Set BRAINSHIFT_WRITE_BASELINES=1 to write a new
// baseline after a deliberate change of the rendering, and look at it before committing it.
#include "BrainShiftTestingSupport.h"
#include "SyntheticData.h"
#include "ThreeDView.h"

#include <vtkImageData.h>
#include <vtkImageDifference.h>
#include <vtkPNGReader.h>
#include <vtkPNGWriter.h>
#include <vtkRenderWindow.h>
#include <vtkScalarBarActor.h>
#include <vtkWindowToImageFilter.h>

#include <QApplication>
#include <QSurfaceFormat>
#include <QTest>

#include <filesystem>
#include <iostream>

namespace {
using namespace brainshift;

vtkSmartPointer<vtkImageData> capture(ThreeDView& view)
{
  view.renderWindow()->Render();
  vtkNew<vtkWindowToImageFilter> grab;
  grab->SetInput(view.renderWindow());
  grab->SetInputBufferTypeToRGB();
  grab->ReadFrontBufferOff();
  grab->Update();
  vtkSmartPointer<vtkImageData> image = grab->GetOutput();
  return image;
}

/// VTK's regression measure (shifts of a pixel forgiven, differences up to 16 grey levels per
/// pixel ignored), as the mean excess per pixel.
double differencePerPixel(vtkImageData* rendered, vtkImageData* baseline)
{
  vtkNew<vtkImageDifference> difference;
  difference->SetThreshold(16);
  difference->SetInputData(rendered);
  difference->SetImageData(baseline);
  difference->Update();
  const int* size = rendered->GetDimensions();
  return difference->GetThresholdedError() / (double(size[0]) * size[1]);
}
} // namespace

int ThreeDViewRenderingTest(int argc, char* argv[])
{
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  QApplication application(argc, argv);
  return brainshift::testing::runTest("ThreeDViewRenderingTest", [] {
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
    const auto rendered = capture(view);
    const int* size = rendered->GetDimensions();
    BS_CHECK_MSG(size[0] == 300 && size[1] == 300, size[0] << "x" << size[1]);

    const std::filesystem::path baselineFile =
      std::filesystem::path(std::getenv("BRAINSHIFT_BASELINES")) / "ThreeDViewDisplacement.png";
    const std::filesystem::path candidate = testing::temporaryFolder("ThreeDViewRenderingTest") / "ThreeDViewDisplacement.png";
    vtkNew<vtkPNGWriter> writer;
    writer->SetInputData(rendered);
    writer->SetFileName(candidate.c_str());
    writer->Write();
    if (std::getenv("BRAINSHIFT_WRITE_BASELINES")) std::filesystem::copy_file(candidate, baselineFile, std::filesystem::copy_options::overwrite_existing);
    BS_CHECK_MSG(std::filesystem::exists(baselineFile), "no baseline " << baselineFile << "; the rendering is in " << candidate);
    vtkNew<vtkPNGReader> reader;
    reader->SetFileName(baselineFile.c_str());
    reader->Update();
    const double error = differencePerPixel(rendered, reader->GetOutput());
    std::cout << "difference from the baseline: " << error << " per pixel (rendering: " << candidate << ")\n";
    BS_CHECK_MSG(error < 0.005, error << "; compare " << candidate << " with " << baselineFile);

    // Without the colouring, the same comparison fails clearly.
    display.scalarVisibility = false;
    surface->setDisplay(display);
    view.setModels({surface});
    BS_CHECK(!view.scalarBar()->GetVisibility());
    const double uncoloured = differencePerPixel(capture(view), reader->GetOutput());
    std::cout << "an uncoloured surface differs by " << uncoloured << " per pixel\n";
    BS_CHECK_MSG(uncoloured > 0.02, uncoloured); // four times the tolerance and more
  });
}
