#pragma once
// Rendering tests against committed baselines (Widgets/Testing/Data/Baseline, 300x300 PNG):
// the view's pixels, VTK's image comparison, and the candidate written where a failing test
// says. BRAINSHIFT_WRITE_BASELINES=1 writes a new baseline after a deliberate change: look at
// it before committing it.
#include "BrainShiftTestingSupport.h"

#include <QVTKOpenGLNativeWidget.h>
#include <vtkImageData.h>
#include <vtkImageDifference.h>
#include <vtkPNGReader.h>
#include <vtkPNGWriter.h>
#include <vtkRenderWindow.h>
#include <vtkWindowToImageFilter.h>

#include <cstdlib>
#include <filesystem>
#include <iostream>

namespace brainshift::testing {

/// The largest differencePerPixel a rendering may have from its baseline (measured here: 0; the
/// tolerance absorbs other Mesa versions' antialiasing of edges and text).
constexpr double renderingTolerance = 0.005;

inline vtkSmartPointer<vtkImageData> capture(QVTKOpenGLNativeWidget& view)
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
inline double differencePerPixel(vtkImageData* rendered, vtkImageData* baseline)
{
  vtkNew<vtkImageDifference> difference;
  difference->SetThreshold(16);
  difference->SetInputData(rendered);
  difference->SetImageData(baseline);
  difference->Update();
  const int* size = rendered->GetDimensions();
  return difference->GetThresholdedError() / (double(size[0]) * size[1]);
}

/// The baseline `name` (written first from `rendered` when BRAINSHIFT_WRITE_BASELINES is set);
/// the rendering is saved beside the test's temporary files either way.
inline vtkSmartPointer<vtkImageData> baseline(const std::string& testName, const std::string& name, vtkImageData* rendered)
{
  const char* folder = std::getenv("BRAINSHIFT_BASELINES");
  BS_CHECK_MSG(folder, "BRAINSHIFT_BASELINES is not set (ctest sets it to Widgets/Testing/Data/Baseline)");
  const std::filesystem::path file = std::filesystem::path(folder) / name;
  const std::filesystem::path candidate = temporaryFolder(testName) / name;
  vtkNew<vtkPNGWriter> writer;
  writer->SetInputData(rendered);
  writer->SetFileName(candidate.c_str());
  writer->Write();
  if (std::getenv("BRAINSHIFT_WRITE_BASELINES")) {
    std::filesystem::copy_file(candidate, file, std::filesystem::copy_options::overwrite_existing);
  }
  BS_CHECK_MSG(std::filesystem::exists(file), "no baseline " << file << "; the rendering is in " << candidate);
  std::cout << "rendering: " << candidate << ", baseline: " << file << '\n';
  vtkNew<vtkPNGReader> reader;
  reader->SetFileName(file.c_str());
  reader->Update();
  vtkSmartPointer<vtkImageData> image = reader->GetOutput();
  return image;
}

} // namespace brainshift::testing
