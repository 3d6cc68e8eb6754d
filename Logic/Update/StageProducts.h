#pragma once
// What the stages of one update made, kept in memory beside the files they wrote: the data bus
// between the stages of a run. A later stage of the same run takes the label volume or the model
// from here instead of reading its file back (the file is still written: it is the output). Each
// entry remembers the file's size and modification time as the stage left it; a file changed since
// (by another program, or a stage run alone in another process) is read again; a rewrite within
// one tick of the file system's clock that keeps the size is not noticed (the stages themselves
// write through here). What is given out is a copy: a stage may change it freely.
#include "ImageTypes.h"

#include <vtkPointSet.h>
#include <vtkSmartPointer.h>

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>

namespace brainshift {

class StageProducts {
public:
  /// The label volume in `file`: the copy kept when this run wrote it, else read (readLabelVolume).
  LabelImage::Pointer readLabelVolume(const std::filesystem::path& file);
  /// Writes it (writeLabelVolume: atomically) and keeps a copy.
  void writeLabelVolume(const LabelImage* labels, const std::filesystem::path& file);
  /// The mesh or surface in `file`, likewise (readModel, writeModel).
  vtkSmartPointer<vtkPointSet> readModel(const std::filesystem::path& file);
  void writeModel(vtkPointSet* model, const std::filesystem::path& file);
  /// How many reads were answered from memory, and how many went to a file.
  std::size_t readsFromMemory() const { return fromMemory_; }
  std::size_t readsFromFiles() const { return fromFiles_; }

private:
  struct Stamp {
    std::uintmax_t size = 0;
    std::filesystem::file_time_type time;
    bool operator==(const Stamp& other) const { return size == other.size && time == other.time; }
  };
  static std::optional<Stamp> stampOf(const std::filesystem::path& file);
  static std::filesystem::path keyOf(const std::filesystem::path& file);
  template <class TProduct>
  struct Kept {
    Stamp stamp;
    TProduct product;
  };
  std::map<std::filesystem::path, Kept<LabelImage::Pointer>> labels_;
  std::map<std::filesystem::path, Kept<vtkSmartPointer<vtkPointSet>>> models_;
  std::size_t fromMemory_ = 0, fromFiles_ = 0;
};

} // namespace brainshift
