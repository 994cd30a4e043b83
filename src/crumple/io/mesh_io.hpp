#pragma once
/// \file
/// Reading and writing triangle meshes: OBJ, PLY, OFF, X3D (see x3d.hpp for the MassSpring node).
///
/// Readers keep vertex and face order exactly as stored (polygons are fan-triangulated in place:
/// polygon (v0..vn-1) becomes (v0,v1,v2), (v0,v2,v3), ...). Every reader throws
/// `crumple::ParseError` naming the file, the line (text) or byte offset (binary) and what was
/// expected; never a crash, hang or silent partial mesh. A missing or unreadable file is a
/// `ParseError` naming the file. Readers reject non-finite coordinates and vertex ids out of
/// range, and faces that repeat a vertex, at the face's line (or byte) with ids as the file
/// numbers them; zero-area faces and the like are left to `TriMesh::create` (`read_mesh`).
/// Text formats accept LF and CRLF line endings.
///
/// Writers write a temporary file beside the target and rename it, so an interrupted write never
/// leaves a half-written file. Text writers print each coordinate as the shortest decimal text
/// that reads back to the same double, so every format round-trips positions bit for bit.
/// Writers check their arguments with `CRUMPLE_CHECK` (finite coordinates, ids in [0, #V)) and
/// throw `PreconditionError` otherwise; a file that cannot be written is a `ParseError`.

#include <crumple/core/types.hpp>
#include <crumple/mesh/mesh.hpp>

#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace crumple::io {

/// Raw mesh data as read from a file, not yet validated (see `TriMesh::create`).
struct MeshData {
  Positions positions;      ///< #V positions, in file order
  std::vector<Face> faces;  ///< #F triangles, in file order (polygons fan-triangulated)
};

enum class MeshFormat { Obj, Ply, Off, X3d };

/// "obj", "ply", "off" or "x3d".
std::string_view to_string(MeshFormat format);

/// Format from the file extension (case-insensitive .obj .ply .off .x3d); throws `InputError`
/// listing the supported extensions otherwise.
MeshFormat format_from_path(const std::filesystem::path& path);

/// Wavefront OBJ. Reads `v x y z [w]` (w ignored; 6 or 7 numbers with a trailing RGB colour are
/// accepted too) and `f` with `i`, `i/vt`, `i//vn` or `i/vt/vn` references (1-based; negative
/// ids count back from the last vertex defined so far; positive ids may refer forward). A line
/// ending in '\' continues on the next line; '#' starts a comment. Other standard statements
/// (vt, vn, o, g, s, usemtl, mtllib, l, p, free-form geometry, ...) are skipped; an unknown
/// statement is an error, so is a face with fewer than 3 vertices or an id 0 / out of range.
MeshData read_obj(const std::filesystem::path& path);
/// Stanford PLY, ascii or binary of either byte order. Vertex `x`, `y`, `z` may have any scalar
/// type and sit anywhere among other properties; faces come from the list property
/// `vertex_indices` (or `vertex_index`) of element `face`, with any integer count and item types.
/// Other elements and properties, lists included, are skipped. A binary body must have exactly
/// the size the header implies; counts that cannot fit in the file are rejected before any
/// allocation. Binary errors name the byte offset, ascii and header errors the line.
MeshData read_ply(const std::filesystem::path& path);
/// Geomview OFF (text), one vertex or face per line. The header keyword may be OFF, COFF, NOFF,
/// CNOFF or STOFF (values after x y z on a vertex line, and a colour after a face's ids, are
/// ignored) or be omitted; the counts may follow it on the same line; '#' starts a comment;
/// nothing but blanks and comments may follow the last face. 4OFF, nOFF and binary OFF are
/// rejected.
MeshData read_off(const std::filesystem::path& path);
/// X3D (XML encoding): the first `IndexedFaceSet`, `IndexedTriangleSet` or `MassSpring` node of
/// the document, in document order. Face sets take positions from a `Coordinate` (or
/// `CoordinateDouble`) child, following `USE` to its `DEF`; `coordIndex` polygons are separated
/// by -1 (the last -1 is optional) and need 3 or more vertices; `index` holds triangles. A
/// `MassSpring` node gives its positions and its `Face` triangles (see x3d.hpp). Transforms
/// are not applied. Errors name the line of the offending element.
MeshData read_x3d(const std::filesystem::path& path);

/// Reads by extension (see `format_from_path`).
MeshData read_mesh_data(const std::filesystem::path& path);
/// Reads by extension and validates with `TriMesh::create`; a validation `InputError` is
/// rethrown as `ParseError` naming the file and, in its message, the element. A file without
/// any face (empty, or points only) is a `ParseError` in every format.
TriMesh read_mesh(const std::filesystem::path& path);

enum class PlyEncoding { Ascii, BinaryLittleEndian, BinaryBigEndian };

/// OBJ with `v x y z` and 1-based `f a b c` lines.
void write_obj(const std::filesystem::path& path, PositionsView positions, std::span<const Face> faces);
/// PLY with double coordinates and `list uchar int vertex_indices`.
void write_ply(const std::filesystem::path& path, PositionsView positions, std::span<const Face> faces,
               PlyEncoding encoding = PlyEncoding::BinaryLittleEndian);
/// OFF with `3 a b c` face lines.
void write_off(const std::filesystem::path& path, PositionsView positions, std::span<const Face> faces);
/// X3D with an `IndexedFaceSet` and a `Coordinate` node.
void write_x3d(const std::filesystem::path& path, PositionsView positions, std::span<const Face> faces);
/// Writes by extension (PLY as binary little-endian).
void write_mesh(const std::filesystem::path& path, PositionsView positions, std::span<const Face> faces);

}  // namespace crumple::io
