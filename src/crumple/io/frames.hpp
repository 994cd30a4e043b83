#pragma once
/// \file
/// A sequence of frames of one deforming mesh, one file per frame (any supported format).

#include <crumple/io/mesh_io.hpp>

#include <filesystem>
#include <vector>

namespace crumple::io {

/// Frame files of one mesh. The first file gives the (validated) mesh; every later frame must
/// have the same vertex count and the same faces in the same order, else `ParseError` names the
/// file and the first difference. Frames are read on demand, in any order.
class FrameSequence {
 public:
  /// Reads the first file. Throws `InputError` if `files` is empty.
  explicit FrameSequence(std::vector<std::filesystem::path> files);

  std::size_t size() const { return files_.size(); }
  const std::filesystem::path& file(std::size_t i) const { return files_.at(i); }
  /// The mesh of the first frame.
  const TriMesh& first() const { return first_; }
  /// Positions of frame i (the first frame's come from memory).
  Positions positions(std::size_t i) const;

 private:
  std::vector<std::filesystem::path> files_;
  TriMesh first_;
};

}  // namespace crumple::io
