#include <crumple/core/error.hpp>
#include <crumple/io/frames.hpp>

namespace crumple::io {

FrameSequence::FrameSequence(std::vector<std::filesystem::path> files)
    : files_(std::move(files)),
      first_(files_.empty() ? throw InputError("no frame files given") : read_mesh(files_.front())) {}

Positions FrameSequence::positions(std::size_t i) const {
  if (i == 0) return first_.positions();
  const std::filesystem::path& path = files_.at(i);
  MeshData data = read_mesh_data(path);
  if (data.positions.size() != static_cast<std::size_t>(first_.num_vertices())) {
    throw ParseError(path.string(), {},
                     "frame has " + std::to_string(data.positions.size()) + " vertices, expected " +
                         std::to_string(first_.num_vertices()) + " as in " +
                         files_.front().string());
  }
  const auto faces = first_.topology().faces();
  if (data.faces.size() != faces.size()) {
    throw ParseError(path.string(), {},
                     "frame has " + std::to_string(data.faces.size()) + " faces, expected " +
                         std::to_string(faces.size()) + " as in " + files_.front().string());
  }
  for (std::size_t f = 0; f < faces.size(); ++f) {
    if (data.faces[f] != faces[f]) {
      throw ParseError(path.string(), {},
                       "face " + std::to_string(f) + " differs from " + files_.front().string() +
                           " (frames must share connectivity)");
    }
  }
  try {
    check_finite(data.positions);
  } catch (const InputError& e) {
    throw ParseError(path.string(), {}, e.what());
  }
  return std::move(data.positions);
}

}  // namespace crumple::io
