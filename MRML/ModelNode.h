#pragma once
// A surface (vtkPolyData) or a tetrahedral mesh (vtkUnstructuredGrid) with point and cell arrays,
// in the LPS frame of its parent transform.
#include "Node.h"

#include <vtkPointSet.h>
#include <vtkSmartPointer.h>

#include <array>
#include <memory>
#include <optional>

namespace brainshift {

struct ModelDisplay {
  std::array<double, 3> color{0.9, 0.8, 0.7};
  double opacity = 1.0;
  bool scalarVisibility = false;
  std::string activeScalarName;         ///< the point (or cell) array that colours the model
  std::string colorTable = "ColdToHotRainbow";
  std::optional<std::array<double, 2>> scalarRange; ///< unset: the array's range
};

class ModelNode : public Node {
public:
  static std::shared_ptr<ModelNode> create(const std::string& name, vtkSmartPointer<vtkPointSet> mesh = nullptr);
  NodeKind kind() const override { return NodeKind::Model; }
  const char* slicerClassName() const override { return "vtkMRMLModelNode"; }

  vtkPointSet* mesh() const { return mesh_; }
  void setMesh(vtkSmartPointer<vtkPointSet> mesh);
  /// True for a tetrahedral (unstructured grid) model, false for a surface.
  bool isVolumetric() const;

  const ModelDisplay& display() const { return display_; }
  void setDisplay(const ModelDisplay& display);

private:
  vtkSmartPointer<vtkPointSet> mesh_;
  ModelDisplay display_;
};

} // namespace brainshift
