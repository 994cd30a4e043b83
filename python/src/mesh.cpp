/// `crumple.TriMesh`, `read_mesh`, `write_mesh`: meshes and their topology as NumPy arrays.

#include "bindings.hpp"

#include <crumple/core/error.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/mesh/mesh.hpp>

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cmath>
#include <optional>

#include <string>
#include <utility>

namespace crumple::python {

namespace {

constexpr py::ssize_t kIndexBytes = sizeof(Index);

/// CSR form of an adjacency: (offsets int64 (rows+1,), neighbours int32 (total,)). The
/// neighbours are a view over the topology's storage (owner kept alive); offsets are computed.
py::tuple adjacency_arrays(const Adjacency& adj, py::handle owner) {
  const Index rows = adj.size();
  py::array_t<std::int64_t> offsets(static_cast<py::ssize_t>(rows) + 1);
  auto o = offsets.mutable_unchecked<1>();
  const Index* base = (rows > 0 && adj.total() > 0) ? adj[0].data() : nullptr;
  o(0) = 0;
  for (Index i = 0; i < rows; ++i) {
    const auto row = adj[i];
    o(i + 1) = base ? static_cast<std::int64_t>(row.data() + row.size() - base) : 0;
  }
  static const Index kEmpty = 0;
  const auto total = static_cast<py::ssize_t>(adj.total());
  return py::make_tuple(offsets, readonly_view<Index>(base ? base : &kEmpty, {total}, {kIndexBytes}, owner));
}

}  // namespace

void bind_mesh(py::module_& m) {
  py::class_<TriMesh> mesh(m, "TriMesh", R"doc(
A validated, immutable triangle mesh: positions plus topology (unique edges, adjacency).
New positions go to `Detector.update`, not into the mesh.

Array properties are read-only views over the mesh's own storage (no copy); they keep the
mesh alive. Vertex and face order are exactly as given; edges are numbered in order of first
appearance over faces f = 0..m-1, sides (v0,v1), (v1,v2), (v2,v0), each as (min id, max id).
)doc");
  mesh.def(py::init([](py::handle vertices, py::handle faces) {
             PositionsArg p = positions_arg(vertices, "vertices");
             const PositionsView x = p.doubles();
             Positions positions = p.copied ? std::move(p.storage) : Positions(x.begin(), x.end());
             return TriMesh::create(std::move(positions), faces_arg(faces));
           }),
           py::arg("vertices"), py::arg("faces"), R"doc(
Builds and validates a mesh (the positions are copied into the mesh).

vertices: (n, 3) real array (float64 or float32; converted to float64).
faces: (m, 3) integer array of vertex ids, 0-based.
Raises ValueError on a wrong shape or dtype, crumple.InputError (a ValueError) naming the
element on a non-finite coordinate, an id out of range or a vertex repeated in a face.
)doc");
  mesh.def_property_readonly("num_vertices", &TriMesh::num_vertices);
  mesh.def_property_readonly("num_faces", &TriMesh::num_faces);
  mesh.def_property_readonly("num_edges", &TriMesh::num_edges);
  mesh.def_property_readonly(
      "vertices",
      [](py::object self) {
        const TriMesh& t = self.cast<const TriMesh&>();
        static const double kEmpty = 0;
        const double* data = t.positions().empty() ? &kEmpty : t.positions().front().data();
        return readonly_view<double>(data, {t.num_vertices(), 3}, {sizeof(Vec3), sizeof(double)}, self);
      },
      "(n, 3) float64, read-only view of the positions.");
  mesh.def_property_readonly(
      "faces",
      [](py::object self) {
        const Topology& topo = self.cast<const TriMesh&>().topology();
        static const Index kEmpty = 0;
        const Index* data = topo.faces().empty() ? &kEmpty : topo.faces().front().data();
        return readonly_view<Index>(data, {topo.num_faces(), 3}, {sizeof(Face), kIndexBytes}, self);
      },
      "(m, 3) int32, read-only view of the faces' vertex ids.");
  mesh.def_property_readonly(
      "edges",
      [](py::object self) {
        const Topology& topo = self.cast<const TriMesh&>().topology();
        static const Index kEmpty = 0;
        const Index* data = topo.edges().empty() ? &kEmpty : topo.edges().front().data();
        return readonly_view<Index>(data, {topo.num_edges(), 2}, {sizeof(Edge), kIndexBytes}, self);
      },
      "(e, 2) int32, read-only view of the unique edges (first id < second id).");
  mesh.def_property_readonly(
      "face_edges",
      [](py::object self) {
        const Topology& topo = self.cast<const TriMesh&>().topology();
        static const Index kEmpty = 0;
        const Index* data = topo.num_faces() == 0 ? &kEmpty : topo.face_edges(0).data();
        return readonly_view<Index>(data, {topo.num_faces(), 3},
                                    {sizeof(std::array<Index, 3>), kIndexBytes}, self);
      },
      "(m, 3) int32, read-only view: edge id of each face's side k (corners k and (k+1)%3).");
  mesh.def(
      "adjacency",
      [](py::object self, const std::string& kind) {
        const Topology& topo = self.cast<const TriMesh&>().topology();
        const Adjacency* adj = nullptr;
        if (kind == "vertex_vertices") adj = &topo.vertex_vertices();
        if (kind == "vertex_edges") adj = &topo.vertex_edges();
        if (kind == "vertex_faces") adj = &topo.vertex_faces();
        if (kind == "edge_faces") adj = &topo.edge_faces();
        if (kind == "edge_edges") adj = &topo.edge_edges();
        if (kind == "face_faces") adj = &topo.face_faces();
        if (!adj) {
          throw py::value_error("adjacency: unknown kind '" + kind +
                                "', expected vertex_vertices, vertex_edges, vertex_faces, "
                                "edge_faces, edge_edges or face_faces");
        }
        return adjacency_arrays(*adj, self);
      },
      py::arg("kind"), R"doc(
Adjacency lists in CSR form: (offsets, neighbours). Row i's neighbours, sorted by increasing
id, are neighbours[offsets[i]:offsets[i+1]].

kind: vertex_vertices (one-ring), vertex_edges, vertex_faces, edge_faces, edge_edges (edges
sharing a vertex, itself excluded) or face_faces (faces sharing a vertex, itself excluded).
Returns offsets: (rows+1,) int64 (computed), neighbours: (total,) int32 (read-only view, no
copy).
)doc");
  mesh.def_property_readonly(
      "report",
      [](const TriMesh& t) {
        const MeshReport& r = t.report();
        py::dict d;
        d["zero_area_faces"] = r.zero_area_faces;
        d["non_manifold_edges"] = r.non_manifold_edges;
        d["boundary_edges"] = r.boundary_edges;
        d["isolated_vertices"] = r.isolated_vertices;
        d["duplicate_faces"] = r.duplicate_faces;
        return d;
      },
      "What validation accepted but counted, as a dict of ints.");
  mesh.def("__repr__", [](const TriMesh& t) {
    return "TriMesh(" + std::to_string(t.num_vertices()) + " vertices, " +
           std::to_string(t.num_faces()) + " faces, " + std::to_string(t.num_edges()) + " edges)";
  });

  m.def(
      "read_mesh", [](const std::filesystem::path& path) { return io::read_mesh(path); },
      py::arg("path"), R"doc(
Reads a mesh by extension (.obj .ply .off .x3d), keeping vertex and face order.
Raises crumple.ParseError (a ValueError, with file, line or byte_offset, and message) on a
missing, unreadable or malformed file, and on a mesh that fails validation.
)doc");
  m.def(
      "write_mesh",
      [](const std::filesystem::path& path, const TriMesh& mesh) {
        io::write_mesh(path, mesh.positions(), mesh.topology().faces());
      },
      py::arg("path"), py::arg("mesh"), R"doc(
Writes a mesh by extension (.obj .ply .off .x3d; PLY as binary little-endian) atomically;
positions round-trip bit for bit. Raises crumple.ParseError when the file cannot be written.
)doc");
  m.def(
      "default_thickness",
      [](py::handle positions, std::optional<double> relative) {
        PositionsArg arg = positions_arg(positions, "positions");
        const PositionsView x = arg.doubles();  // may view arg's storage: arg outlives it
        if (!relative) return default_thickness(x);
        if (!(std::isfinite(*relative) && *relative >= 0)) {
          throw InputError("default_thickness: relative must be a finite number >= 0");
        }
        return *relative * compute_bounds(x).diagonal();
      },
      py::arg("positions"), py::kw_only(), py::arg("relative") = py::none(),
      "The thickness the CLI uses when none is given: 1e-3 of the bounding-box diagonal of "
      "(n, 3) positions; with relative=r, r times that diagonal (the CLI's --thickness-rel r).");
}

}  // namespace crumple::python
