#pragma once
// Surfaces (.vtp) and tetrahedral meshes (.vtu) in VTK's XML formats, and legacy .vtk files.
// BrainShift's models are in LPS mm; the files say so (see ModelIO.cxx) so that 3D Slicer, whose
// world is RAS, places them right.
#include <vtkPointSet.h>
#include <vtkSmartPointer.h>

#include <filesystem>

namespace brainshift {

/// Reads a .vtp, .vtu or .vtk file into LPS. A file tagged RAS is converted (x and y negated).
/// InputError naming the file if it is missing, unreadable, or has no points.
vtkSmartPointer<vtkPointSet> readModel(const std::filesystem::path& path);

/// Writes atomically: vtkPolyData to .vtp (or .vtk), vtkUnstructuredGrid to .vtu (or .vtk),
/// tagged as LPS.
void writeModel(vtkPointSet* model, const std::filesystem::path& path);

} // namespace brainshift
