// Format dispatch and validated reading.

#include <crumple/io/mesh_io.hpp>

#include <crumple/core/error.hpp>
#include <crumple/io/io_detail.hpp>

#include <algorithm>
#include <cctype>

namespace crumple::io {

std::string_view to_string(MeshFormat format) {
  switch (format) {
    case MeshFormat::Obj: return "obj";
    case MeshFormat::Ply: return "ply";
    case MeshFormat::Off: return "off";
    case MeshFormat::X3d: return "x3d";
  }
  return "?";
}

MeshFormat format_from_path(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".obj") return MeshFormat::Obj;
  if (ext == ".ply") return MeshFormat::Ply;
  if (ext == ".off") return MeshFormat::Off;
  if (ext == ".x3d") return MeshFormat::X3d;
  throw InputError("cannot tell the mesh format of '" + path.string() + "' from its extension " +
                   (ext.empty() ? std::string("(none)") : "'" + ext + "'") +
                   ": expected .obj, .ply, .off or .x3d");
}

MeshData read_mesh_data(const std::filesystem::path& path) {
  switch (format_from_path(path)) {
    case MeshFormat::Obj: return read_obj(path);
    case MeshFormat::Ply: return read_ply(path);
    case MeshFormat::Off: return read_off(path);
    case MeshFormat::X3d: return read_x3d(path);
  }
  return {};
}

TriMesh read_mesh(const std::filesystem::path& path) {
  MeshData data = read_mesh_data(path);
  // Valid in every format (a PLY with zero faces, an OBJ with no statement), but not a mesh:
  // every format says so the same way.
  if (data.faces.empty()) {
    throw ParseError(path.string(), {},
                     "no faces: a triangle mesh needs at least one (the file holds " +
                         std::to_string(data.positions.size()) + " vertices and no face)");
  }
  try {
    return TriMesh::create(std::move(data.positions), std::move(data.faces));
  } catch (const InputError& e) {
    throw ParseError(path.string(), {}, std::string("invalid mesh: ") + e.what());
  }
}

void write_mesh(const std::filesystem::path& path, PositionsView positions,
                std::span<const Face> faces) {
  switch (format_from_path(path)) {
    case MeshFormat::Obj: write_obj(path, positions, faces); return;
    case MeshFormat::Ply: write_ply(path, positions, faces); return;
    case MeshFormat::Off: write_off(path, positions, faces); return;
    case MeshFormat::X3d: write_x3d(path, positions, faces); return;
  }
}

}  // namespace crumple::io
