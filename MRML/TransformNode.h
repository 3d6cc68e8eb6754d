#pragma once
// A spatial transform: linear, a displacement field, or a composition. It holds the transform
// *from its parent*: the resampling transform that maps a point of the parent (world) frame to
// the point of this node's child frame that it shows. This is what ITK transform files store
// and what ../shared/CONTRACT.md calls `intraop_to_preop` when the world is the intraoperative
// frame and the preoperative data are placed under this node.
#include "Node.h"
#include "TransformIO.h"

#include <memory>

namespace brainshift {

class TransformNode : public Node {
public:
  enum class Type { Linear, DisplacementField, Composite };

  static std::shared_ptr<TransformNode> create(const std::string& name, SpatialTransform::Pointer fromParent = nullptr);
  NodeKind kind() const override { return NodeKind::Transform; }
  /// Slicer saves linear transforms as LinearTransform, fields as GridTransform, others as Transform.
  const char* slicerClassName() const override;

  const SpatialTransform* transformFromParent() const { return transform_.GetPointer(); }
  void setTransformFromParent(SpatialTransform::Pointer transform);
  Type type() const;

private:
  SpatialTransform::Pointer transform_;
};

} // namespace brainshift
