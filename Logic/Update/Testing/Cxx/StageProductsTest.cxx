// The data bus between the stages of one run (StageProducts): what a stage wrote is read back from
// memory while its file is as the stage left it, as a copy a reader may change freely; a file
// written since by anyone else is read from disk; a file never written through it is read from
// disk; the files themselves are always written.
#include "BrainShiftTestingSupport.h"
#include "ModelIO.h"
#include "StageProducts.h"
#include "VolumeIO.h"

#include <vtkNew.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>

#include <chrono>

namespace {
using namespace brainshift;
namespace fs = std::filesystem;

LabelImage::Pointer labelsFilledWith(LabelPixel value)
{
  auto labels = LabelImage::New();
  LabelImage::SizeType size;
  size.Fill(6);
  labels->SetRegions(size);
  const double spacing[3] = {1.0, 1.5, 2.0};
  labels->SetSpacing(spacing);
  labels->Allocate();
  labels->FillBuffer(value);
  return labels;
}

vtkSmartPointer<vtkPolyData> surfaceAt(double x)
{
  vtkNew<vtkPoints> points;
  points->InsertNextPoint(x, 0, 0);
  points->InsertNextPoint(x, 1, 0);
  points->InsertNextPoint(x, 0, 1);
  auto surface = vtkSmartPointer<vtkPolyData>::New();
  surface->SetPoints(points);
  return surface;
}
} // namespace

int StageProductsTest(int, char*[])
{
  return brainshift::testing::runTest("StageProductsTest", [] {
    const fs::path folder = brainshift::testing::temporaryFolder("StageProductsTest");
    const fs::path labelsFile = folder / "intraop_labels.nii.gz", surfaceFile = folder / "brain_surface.vtp";
    StageProducts products;

    // Written through it: the file is there, and reading gives the same voxels from memory.
    products.writeLabelVolume(labelsFilledWith(2), labelsFile);
    BS_CHECK(fs::exists(labelsFile));
    LabelImage::Pointer first = products.readLabelVolume(labelsFile);
    BS_CHECK(first->GetBufferPointer()[0] == 2 && products.readsFromMemory() == 1 && products.readsFromFiles() == 0);
    BS_CHECK_NEAR(first->GetSpacing()[2], 2.0, 0);
    // A copy: changing it changes neither what is kept nor the file.
    first->FillBuffer(4);
    BS_CHECK(products.readLabelVolume(labelsFile)->GetBufferPointer()[0] == 2);
    BS_CHECK(readLabelVolume(labelsFile)->GetBufferPointer()[0] == 2);

    // Written since by someone else (a later time stamp, set so whatever the file system's clock
    // resolution): read from the file, with its contents.
    writeLabelVolume(labelsFilledWith(3), labelsFile);
    fs::last_write_time(labelsFile, fs::last_write_time(labelsFile) + std::chrono::seconds(2));
    const std::size_t filesBefore = products.readsFromFiles();
    BS_CHECK(products.readLabelVolume(labelsFile)->GetBufferPointer()[0] == 3);
    BS_CHECK(products.readsFromFiles() == filesBefore + 1);

    // A file never written through it is read from disk; a missing one is the reader's error.
    const fs::path other = folder / "other_labels.nii.gz";
    writeLabelVolume(labelsFilledWith(1), other);
    BS_CHECK(products.readLabelVolume(other)->GetBufferPointer()[0] == 1);
    BS_CHECK_THROWS(products.readLabelVolume(folder / "missing.nii.gz"), std::exception, "missing.nii.gz");

    // Models the same way: the kept copy is independent of the writer's object and of the reader's.
    vtkSmartPointer<vtkPolyData> surface = surfaceAt(5.0);
    products.writeModel(surface, surfaceFile);
    surface->GetPoints()->SetPoint(0, 9, 9, 9); // the stage goes on changing its own object
    const std::size_t memoryBefore = products.readsFromMemory();
    vtkSmartPointer<vtkPointSet> read = products.readModel(surfaceFile);
    BS_CHECK(products.readsFromMemory() == memoryBefore + 1);
    BS_CHECK(vtkPolyData::SafeDownCast(read) != nullptr && read->GetNumberOfPoints() == 3);
    BS_CHECK_NEAR(read->GetPoint(0)[0], 5.0, 0);
    read->GetPoints()->SetPoint(1, -1, -1, -1);
    BS_CHECK_NEAR(products.readModel(surfaceFile)->GetPoint(1)[0], 5.0, 0);
    writeModel(surfaceAt(7.0), surfaceFile);
    fs::last_write_time(surfaceFile, fs::last_write_time(surfaceFile) + std::chrono::seconds(2));
    BS_CHECK_NEAR(products.readModel(surfaceFile)->GetPoint(0)[0], 7.0, 0);
  });
}
