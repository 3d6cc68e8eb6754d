#pragma once
// Named landmark pairs (preoperative and intraoperative positions, LPS mm).
#include "LandmarkIO.h"
#include "Node.h"

#include <memory>
#include <vector>

namespace brainshift {

class LandmarksNode : public Node {
public:
  static std::shared_ptr<LandmarksNode> create(const std::string& name, std::vector<LandmarkPair> pairs = {});
  NodeKind kind() const override { return NodeKind::Landmarks; }
  /// Saved as Slicer markups: two fiducial lists, "<name> preop" and "<name> intraop".
  const char* slicerClassName() const override { return "vtkMRMLMarkupsFiducialNode"; }

  const std::vector<LandmarkPair>& pairs() const { return pairs_; }
  void setPairs(std::vector<LandmarkPair> pairs);

private:
  std::vector<LandmarkPair> pairs_;
};

} // namespace brainshift
