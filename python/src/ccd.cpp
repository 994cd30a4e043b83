/// `crumple.ContinuousQuery`, `crumple.Impacts`, `crumple.continuous_impacts` and
/// `crumple.collision_free_step`: continuous collision detection (detect/continuous.hpp) on
/// NumPy positions, impacts returned as NumPy views over the library's impact records.

#include "bindings.hpp"

#include <crumple/detect/continuous.hpp>
#include <crumple/detect/method.hpp>
#include <crumple/geometry/ccd.hpp>
#include <crumple/mesh/mesh.hpp>

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

namespace crumple::python {

namespace {

using ImpactsPtr = std::shared_ptr<const ImpactSet>;

/// The impacts of one query (`crumple.Impacts`); every array made from it keeps `set` alive.
struct PyImpacts {
  ImpactsPtr set;
};
struct VfImpactsView {
  ImpactsPtr set;
};
struct EeImpactsView {
  ImpactsPtr set;
};

ContinuousOptions make_options(double min_separation, const std::string& method, int threads, double time_tolerance,
                               double distance_tolerance, double separation_tolerance, std::int64_t max_boxes) {
  ContinuousOptions options;
  options.min_separation = min_separation;
  options.method = MethodSpec::parse(method);
  options.threads = threads;
  options.narrow.time_tolerance = time_tolerance;
  options.narrow.distance_tolerance = distance_tolerance;
  options.narrow.separation_tolerance = separation_tolerance;
  options.narrow.max_boxes = max_boxes;
  return options;
}

/// The Python query: the library's `ContinuousQuery`, the reusable impact buffer and a guard
/// against two threads using one query while the GIL is released.
class PyContinuousQuery {
 public:
  PyContinuousQuery(const TriMesh& mesh, ContinuousOptions options)
      : query_(mesh.topology_ptr(), std::move(options)) {}

  std::unique_lock<std::mutex> guard() {
    std::unique_lock lock(busy_, std::try_to_lock);
    if (!lock) throw std::runtime_error("ContinuousQuery is in use by another thread");
    return lock;
  }

  PyImpacts query(py::handle previous, py::handle current) {
    const auto lock = guard();
    PositionsArg x0 = positions_arg(previous, "previous");
    PositionsArg x1 = positions_arg(current, "current");
    const auto n = static_cast<std::size_t>(query_.topology().num_vertices());
    if (x0.view.size() != n || x1.view.size() != n) {
      throw py::value_error("ContinuousQuery.query: previous has " + std::to_string(x0.view.size()) +
                            " rows, current " + std::to_string(x1.view.size()) + ", the topology " +
                            std::to_string(n) + " vertices");
    }
    // Reuse the last result's records when Python no longer holds them, otherwise a fresh set:
    // a live `Impacts` is never modified.
    std::shared_ptr<ImpactSet> out = buffer_ && buffer_.use_count() == 1 ? buffer_ : std::make_shared<ImpactSet>();
    buffer_.reset();
    {
      py::gil_scoped_release release;
      const PositionsView p0 = x0.doubles(), p1 = x1.doubles();
      last_copied_ = x0.copied || x1.copied;
      query_.query(p0, p1, *out);
    }
    buffer_ = out;
    return PyImpacts{std::move(out)};
  }

  const ContinuousQuery& inner() const { return query_; }
  bool last_copied() const { return last_copied_; }

 private:
  ContinuousQuery query_;
  std::shared_ptr<ImpactSet> buffer_;
  std::mutex busy_;
  bool last_copied_ = false;
};

/// Positions of a one-shot call as doubles (`what` names the argument), with the mesh's count.
PositionsView one_shot_positions(PositionsArg& arg, const TriMesh& mesh, const char* what) {
  if (arg.view.size() != static_cast<std::size_t>(mesh.num_vertices())) {
    throw py::value_error(std::string(what) + ": " + std::to_string(arg.view.size()) + " rows, the mesh has " +
                          std::to_string(mesh.num_vertices()) + " vertices");
  }
  return arg.doubles();
}

constexpr const char* kOptionsDoc = R"doc(
min_separation: delta >= 0 in scene units (finite); pairs that come within it are impacts.
method: the broad phase, kdop (always swept), hash or sap, with parameters as the CLI's
  `ccd --method` (max_contacts and overflow are ignored).
threads: worker threads, 0 = all hardware threads, 1 = serial; the impacts do not depend on it.
time_tolerance, distance_tolerance, separation_tolerance, max_boxes: the narrow phase's options
  (geometry/ccd.hpp; the CLI's --time-tolerance and --max-boxes are the first and last).
Raises crumple.InputError (a ValueError) on a bad method, parameter, delta or option.)doc";

}  // namespace

void bind_ccd(py::module_& m) {
  py::class_<VfImpactsView>(m, "VertexFaceImpacts", R"doc(
Vertex-face impacts of one query, k rows sorted by (vertex, face). Every array is a read-only
view over the library's records (no copy).
)doc")
      .def("__len__", [](const VfImpactsView& v) { return v.set->vf.size(); })
      .def_property_readonly("vertex", [](py::object self) {
        const auto& r = self.cast<const VfImpactsView&>().set->vf;
        return column<Index>(r, r.empty() ? nullptr : &r[0].vertex, {}, {}, self);
      }, "(k,) int32 vertex ids.")
      .def_property_readonly("face", [](py::object self) {
        const auto& r = self.cast<const VfImpactsView&>().set->vf;
        return column<Index>(r, r.empty() ? nullptr : &r[0].face, {}, {}, self);
      }, "(k,) int32 face ids (the vertex is not a corner of the face).")
      .def_property_readonly("toi", [](py::object self) {
        const auto& r = self.cast<const VfImpactsView&>().set->vf;
        return column<double>(r, r.empty() ? nullptr : &r[0].toi, {}, {}, self);
      }, "(k,) float64 conservative time of impact in [0, 1]: no earlier time brings the pair within delta.")
      .def_property_readonly("distance", [](py::object self) {
        const auto& r = self.cast<const VfImpactsView&>().set->vf;
        return column<double>(r, r.empty() ? nullptr : &r[0].distance, {}, {}, self);
      }, "(k,) float64 distance from the vertex to the face at toi.")
      .def_property_readonly("barycentric", [](py::object self) {
        const auto& r = self.cast<const VfImpactsView&>().set->vf;
        return column<double>(r, r.empty() ? nullptr : r[0].barycentric.data(), {3}, {8}, self);
      }, "(k, 3) float64 barycentric coordinates at toi of the closest point w.r.t. the face's corners.")
      .def_property_readonly("normal", [](py::object self) {
        const auto& r = self.cast<const VfImpactsView&>().set->vf;
        return column<double>(r, r.empty() ? nullptr : r[0].normal.data(), {3}, {8}, self);
      }, "(k, 3) float64 unit vector at toi from the closest point on the face towards the vertex.")
      .def_property_readonly("outcome", [](py::object self) {
        const auto& r = self.cast<const VfImpactsView&>().set->vf;
        return column<std::uint8_t>(r, r.empty() ? nullptr : reinterpret_cast<const std::uint8_t*>(&r[0].outcome), {},
                                    {}, self);
      }, "(k,) uint8 how the narrow phase decided: an index into crumple.ccd_outcomes().");

  py::class_<EeImpactsView>(m, "EdgeEdgeImpacts", R"doc(
Edge-edge impacts of one query, k rows sorted by the vertex ids of edge a, then of edge b.
Read-only views over the library's records (no copy).
)doc")
      .def("__len__", [](const EeImpactsView& v) { return v.set->ee.size(); })
      .def_property_readonly("edges", [](py::object self) {
        const auto& r = self.cast<const EeImpactsView&>().set->ee;
        const py::ssize_t step = r.empty() ? 4 : gap(&r[0].edge0, &r[0].edge1);
        return column<Index>(r, r.empty() ? nullptr : &r[0].edge0, {2}, {step}, self);
      }, "(k, 2) int32 mesh edge ids (a, b).")
      .def_property_readonly("vertices", [](py::object self) {
        const auto& r = self.cast<const EeImpactsView&>().set->ee;
        const py::ssize_t step = r.empty() ? 8 : gap(r[0].a.data(), r[0].b.data());
        return column<Index>(r, r.empty() ? nullptr : r[0].a.data(), {2, 2}, {step, 4}, self);
      }, "(k, 2, 2) int32 vertex ids: [i, 0] = edge a (increasing ids), [i, 1] = edge b; a < b.")
      .def_property_readonly("toi", [](py::object self) {
        const auto& r = self.cast<const EeImpactsView&>().set->ee;
        return column<double>(r, r.empty() ? nullptr : &r[0].toi, {}, {}, self);
      }, "(k,) float64 conservative time of impact in [0, 1].")
      .def_property_readonly("distance", [](py::object self) {
        const auto& r = self.cast<const EeImpactsView&>().set->ee;
        return column<double>(r, r.empty() ? nullptr : &r[0].distance, {}, {}, self);
      }, "(k,) float64 distance between the edges at toi.")
      .def_property_readonly("s", [](py::object self) {
        const auto& r = self.cast<const EeImpactsView&>().set->ee;
        return column<double>(r, r.empty() ? nullptr : &r[0].s, {}, {}, self);
      }, "(k,) float64: at toi the closest point on a is (1-s) a0 + s a1.")
      .def_property_readonly("t", [](py::object self) {
        const auto& r = self.cast<const EeImpactsView&>().set->ee;
        return column<double>(r, r.empty() ? nullptr : &r[0].t, {}, {}, self);
      }, "(k,) float64: at toi the closest point on b is (1-t) b0 + t b1.")
      .def_property_readonly("normal", [](py::object self) {
        const auto& r = self.cast<const EeImpactsView&>().set->ee;
        return column<double>(r, r.empty() ? nullptr : r[0].normal.data(), {3}, {8}, self);
      }, "(k, 3) float64 unit vector at toi from the closest point on a towards the one on b.")
      .def_property_readonly("outcome", [](py::object self) {
        const auto& r = self.cast<const EeImpactsView&>().set->ee;
        return column<std::uint8_t>(r, r.empty() ? nullptr : reinterpret_cast<const std::uint8_t*>(&r[0].outcome), {},
                                    {}, self);
      }, "(k,) uint8 how the narrow phase decided: an index into crumple.ccd_outcomes().");

  py::class_<PyImpacts>(m, "Impacts", R"doc(
The impacts of one continuous query, sorted. `vf` and `ee` give NumPy views over the records
the library filled (no element is copied); an `Impacts` and its arrays stay valid after later
queries (the query then fills a new buffer).
)doc")
      .def_property_readonly("vf", [](const PyImpacts& c) { return VfImpactsView{c.set}; })
      .def_property_readonly("ee", [](const PyImpacts& c) { return EeImpactsView{c.set}; })
      .def_property_readonly(
          "collision_free_step", [](const PyImpacts& c) { return collision_free_step(*c.set); },
          "float: the largest step t in [0, 1] these impacts allow, the earliest toi (1 without impacts).")
      .def("__len__", [](const PyImpacts& c) { return c.set->size(); })
      .def(
          "write", [](const PyImpacts& c, const std::filesystem::path& path) { write_impacts_file(path, *c.set); },
          py::arg("path"),
          "Writes the CLI's `ccd --impacts` text format ('vf V F toi w0 w1 w2 nx ny nz', "
          "'ee A0 A1 B0 B1 toi s t nx ny nz'), atomically.")
      .def("__repr__", [](const PyImpacts& c) {
        return "Impacts(vf=" + std::to_string(c.set->vf.size()) + ", ee=" + std::to_string(c.set->ee.size()) + ")";
      });

  py::class_<PyContinuousQuery>(m, "ContinuousQuery", R"doc(
Continuous collision detection over one mesh's topology, kept across steps (the broad phase is
refitted, not rebuilt): `query(previous, current)` every step. Every vertex moves linearly from
previous to current over t in [0, 1]; an impact is a vertex-face or edge-edge pair sharing no
vertex that comes within min_separation at some t, with a conservative time of impact. No pair
that comes within delta is missed; the impacts are the same, bit for bit, for every method and
thread count.
)doc")
      .def(py::init([](const TriMesh& mesh, double min_separation, const std::string& method, int threads,
                       double time_tolerance, double distance_tolerance, double separation_tolerance,
                       std::int64_t max_boxes) {
             return std::make_unique<PyContinuousQuery>(
                 mesh, make_options(min_separation, method, threads, time_tolerance, distance_tolerance,
                                    separation_tolerance, max_boxes));
           }),
           py::arg("mesh"), py::kw_only(), py::arg("min_separation") = 0.0, py::arg("method") = "kdop",
           py::arg("threads") = 0, py::arg("time_tolerance") = 1e-6, py::arg("distance_tolerance") = 1e-6,
           py::arg("separation_tolerance") = 0.01, py::arg("max_boxes") = 10000,
           (std::string("mesh: a TriMesh whose topology is queried (its positions are not used).") + kOptionsDoc)
               .c_str())
      .def("query", &PyContinuousQuery::query, py::arg("previous"), py::arg("current"), R"doc(
The impacts of the step from previous to current, two (n, 3) real arrays with n = the mesh's
vertex count. float64 C-contiguous arrays are read in place; other dtypes and layouts are
converted to float64 once (see last_positions_copied). The GIL is released while querying.
Raises ValueError on a wrong shape or count, crumple.InputError on a non-finite coordinate.
Returns an Impacts.
)doc")
      .def_property_readonly("stats", [](PyContinuousQuery& q) {
        const auto lock = q.guard();
        py::dict out;
        for (const auto& [key, value] : q.inner().stats().items()) out[py::str(key)] = value;
        return out;
      }, "Counters and ms of the last query (the CLI's `ccd --json` 'stats'), dict str -> float.")
      .def_property_readonly("last_positions_copied", &PyContinuousQuery::last_copied,
                             "Whether the last query converted its positions to float64 (not float64 "
                             "C-contiguous) rather than reading them in place.")
      .def_property_readonly("min_separation",
                             [](const PyContinuousQuery& q) { return q.inner().options().min_separation; })
      .def_property_readonly("method",
                             [](const PyContinuousQuery& q) { return q.inner().options().method.to_string(); },
                             "The canonical method spec.")
      .def_property_readonly("threads", [](const PyContinuousQuery& q) { return q.inner().options().threads; });

  m.def(
      "continuous_impacts",
      [](const TriMesh& mesh, py::handle previous, py::handle current, double min_separation,
         const std::string& method, int threads, double time_tolerance, double distance_tolerance,
         double separation_tolerance, std::int64_t max_boxes) {
        const ContinuousOptions options = make_options(min_separation, method, threads, time_tolerance,
                                                       distance_tolerance, separation_tolerance, max_boxes);
        PositionsArg x0 = positions_arg(previous, "previous");
        PositionsArg x1 = positions_arg(current, "current");
        auto out = std::make_shared<ImpactSet>();
        {
          py::gil_scoped_release release;
          const PositionsView p0 = one_shot_positions(x0, mesh, "previous");
          const PositionsView p1 = one_shot_positions(x1, mesh, "current");
          *out = continuous_impacts(mesh.topology_ptr(), p0, p1, options);
        }
        return PyImpacts{std::move(out)};
      },
      py::arg("mesh"), py::arg("previous"), py::arg("current"), py::kw_only(), py::arg("min_separation") = 0.0,
      py::arg("method") = "kdop", py::arg("threads") = 0, py::arg("time_tolerance") = 1e-6,
      py::arg("distance_tolerance") = 1e-6, py::arg("separation_tolerance") = 0.01, py::arg("max_boxes") = 10000,
      (std::string("The impacts of one step from previous to current ((n, 3) real arrays), as "
                   "ContinuousQuery(mesh, ...).query(previous, current). Returns an Impacts.") +
       kOptionsDoc)
          .c_str());

  m.def(
      "collision_free_step",
      [](const TriMesh& mesh, py::handle previous, py::handle current, double min_separation,
         const std::string& method, int threads, double time_tolerance, double distance_tolerance,
         double separation_tolerance, std::int64_t max_boxes) {
        const ContinuousOptions options = make_options(min_separation, method, threads, time_tolerance,
                                                       distance_tolerance, separation_tolerance, max_boxes);
        PositionsArg x0 = positions_arg(previous, "previous");
        PositionsArg x1 = positions_arg(current, "current");
        py::gil_scoped_release release;
        const PositionsView p0 = one_shot_positions(x0, mesh, "previous");
        const PositionsView p1 = one_shot_positions(x1, mesh, "current");
        return collision_free_step(mesh.topology_ptr(), p0, p1, options);
      },
      py::arg("mesh"), py::arg("previous"), py::arg("current"), py::kw_only(), py::arg("min_separation") = 0.0,
      py::arg("method") = "kdop", py::arg("threads") = 0, py::arg("time_tolerance") = 1e-6,
      py::arg("distance_tolerance") = 1e-6, py::arg("separation_tolerance") = 0.01, py::arg("max_boxes") = 10000,
      (std::string("float: the largest step t in [0, 1] that brings no pair within min_separation, the "
                   "earliest conservative toi of the step from previous to current ((n, 3) real arrays), "
                   "or 1.") +
       kOptionsDoc)
          .c_str());

  m.def("ccd_outcomes", [] {
    py::list out;
    for (int o = 0; o <= static_cast<int>(geometry::CcdOutcome::kHitOutOfRange); ++o) {
      out.append(std::string(geometry::to_string(static_cast<geometry::CcdOutcome>(o))));
    }
    return out;
  }, "The narrow phase's outcome names, indexed by an impact's `outcome` code: 'hit-tolerance' is a "
     "certified near-contact; 'hit-precision', 'hit-budget', 'hit-out-of-range' are conservative only "
     "(possibly false positives).");
}

}  // namespace crumple::python
