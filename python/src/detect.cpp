/// `crumple.Detector` and `crumple.Contacts`: detection on NumPy positions, contacts returned as
/// NumPy views over the library's contact records.

#include "bindings.hpp"

#include <crumple/detect/contact.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/detect/method.hpp>
#include <crumple/mesh/mesh.hpp>

#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <chrono>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

namespace crumple::python {

namespace {

using SetPtr = std::shared_ptr<const ContactSet>;

/// One kind of contacts of one `Contacts` result; arrays keep the records alive.
struct VfView {
  SetPtr set;
};
struct EeView {
  SetPtr set;
};
struct TtView {
  SetPtr set;
};

/// The Python detector: the library detector, the reusable contact buffer and a guard against
/// two threads using one detector while the GIL is released.
class PyDetector {
 public:
  PyDetector(const std::string& method, double thickness, const std::string& kinds, int threads)
      : spec_(MethodSpec::parse(method)) {
    DetectorOptions options;
    options.thickness = thickness;
    options.kinds = ContactKinds::parse(kinds);
    options.threads = threads;
    detector_ = make_detector(spec_, options);
  }

  /// Exclusive use of the detector, or RuntimeError while another thread runs an update.
  std::unique_lock<std::mutex> guard() {
    std::unique_lock lock(busy_, std::try_to_lock);
    if (!lock) throw std::runtime_error("Detector is in use by another thread");
    return lock;
  }

  void set_topology(const TriMesh& mesh) {
    const auto lock = guard();
    detector_->set_topology(mesh.topology_ptr());
    has_topology_ = true;
  }

  PyContacts update(py::handle previous, py::handle positions) {
    const auto lock = guard();
    if (!has_topology_) throw std::runtime_error("Detector.update: call set_topology(mesh) first");
    PositionsArg current = positions_arg(positions, "positions");
    PositionsArg before;
    if (!previous.is_none()) before = positions_arg(previous, "previous");
    const auto n = static_cast<std::size_t>(detector_->topology().num_vertices());
    if (current.view.size() != n || (!previous.is_none() && before.view.size() != n)) {
      throw py::value_error("Detector.update: positions have " + std::to_string(current.view.size()) +
                            (previous.is_none() ? std::string()
                                                : " (previous " + std::to_string(before.view.size()) + ")") +
                            " rows, the topology " + std::to_string(n) + " vertices");
    }
    // Where the positions were converted to float64, if anywhere (the detector converts
    // `previous` only for methods that use motion).
    const bool motion = detector_->capabilities().uses_motion && !previous.is_none();
    last_conversion_ = current.copied || before.copied ? "binding"
                       : !current.view.is_native() || (motion && !before.view.is_native()) ? "detector"
                                                                                          : "none";
    // Reuse the last result's records when Python no longer holds them (the library rewrites
    // records in place), otherwise a fresh set: a live `Contacts` is never modified.
    std::shared_ptr<ContactSet> out =
        buffer_ && buffer_.use_count() == 1 ? buffer_ : std::make_shared<ContactSet>();
    buffer_.reset();
    {
      py::gil_scoped_release release;
      check_finite(current.view);
      check_finite(before.view);
      const auto start = std::chrono::steady_clock::now();
      detector_->update(before.view, current.view, *out);
      last_update_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    }
    buffer_ = out;
    return PyContacts{std::move(out)};
  }

  const Detector& detector() const { return *detector_; }
  Detector& detector() { return *detector_; }
  const MethodSpec& spec() const { return spec_; }
  const char* last_conversion() const { return last_conversion_; }
  double last_update_ms() const { return last_update_ms_; }
  bool has_topology() const { return has_topology_; }

 private:
  MethodSpec spec_;
  std::unique_ptr<Detector> detector_;
  std::shared_ptr<ContactSet> buffer_;
  std::mutex busy_;
  bool has_topology_ = false;
  const char* last_conversion_ = "none";
  double last_update_ms_ = 0;
};

py::dict capabilities_dict(const Capabilities& c) {
  py::dict d;
  d["exact"] = c.exact;
  d["stochastic"] = c.stochastic;
  d["uses_motion"] = c.uses_motion;
  return d;
}

}  // namespace

void bind_detect(py::module_& m) {
  py::class_<VfView>(m, "VertexFaceContacts", R"doc(
Vertex-face contacts of one result, k rows in canonical order (by vertex, then face). Every
array is a read-only view over the library's records (stride 64 bytes, no copy).
)doc")
      .def("__len__", [](const VfView& v) { return v.set->vf.size(); })
      .def_property_readonly("vertex", [](py::object self) {
        const auto& r = self.cast<const VfView&>().set->vf;
        return column<Index>(r, r.empty() ? nullptr : &r[0].vertex, {}, {}, self);
      }, "(k,) int32 vertex ids.")
      .def_property_readonly("face", [](py::object self) {
        const auto& r = self.cast<const VfView&>().set->vf;
        return column<Index>(r, r.empty() ? nullptr : &r[0].face, {}, {}, self);
      }, "(k,) int32 face ids (the vertex is not a corner of the face).")
      .def_property_readonly("distance", [](py::object self) {
        const auto& r = self.cast<const VfView&>().set->vf;
        return column<double>(r, r.empty() ? nullptr : &r[0].distance, {}, {}, self);
      }, "(k,) float64 distance from the vertex to the face (< thickness).")
      .def_property_readonly("barycentric", [](py::object self) {
        const auto& r = self.cast<const VfView&>().set->vf;
        return column<double>(r, r.empty() ? nullptr : r[0].barycentric.data(), {3}, {8}, self);
      }, "(k, 3) float64 barycentric coordinates of the closest point w.r.t. the face's corners.")
      .def_property_readonly("normal", [](py::object self) {
        const auto& r = self.cast<const VfView&>().set->vf;
        return column<double>(r, r.empty() ? nullptr : r[0].normal.data(), {3}, {8}, self);
      }, "(k, 3) float64 unit vector from the closest point on the face towards the vertex.");

  py::class_<EeView>(m, "EdgeEdgeContacts", R"doc(
Edge-edge contacts of one result, k rows in canonical order (by the vertex ids of edge a, then
of edge b). Read-only views over the library's records (stride 72 bytes, no copy).
)doc")
      .def("__len__", [](const EeView& v) { return v.set->ee.size(); })
      .def_property_readonly("edges", [](py::object self) {
        const auto& r = self.cast<const EeView&>().set->ee;
        const py::ssize_t step = r.empty() ? 4 : gap(&r[0].edge0, &r[0].edge1);
        return column<Index>(r, r.empty() ? nullptr : &r[0].edge0, {2}, {step}, self);
      }, "(k, 2) int32 mesh edge ids (a, b).")
      .def_property_readonly("vertices", [](py::object self) {
        const auto& r = self.cast<const EeView&>().set->ee;
        const py::ssize_t step = r.empty() ? 8 : gap(r[0].a.data(), r[0].b.data());
        return column<Index>(r, r.empty() ? nullptr : r[0].a.data(), {2, 2}, {step, 4}, self);
      }, "(k, 2, 2) int32 vertex ids: [i, 0] = edge a (increasing ids), [i, 1] = edge b; a < b.")
      .def_property_readonly("s", [](py::object self) {
        const auto& r = self.cast<const EeView&>().set->ee;
        return column<double>(r, r.empty() ? nullptr : &r[0].s, {}, {}, self);
      }, "(k,) float64: closest point on a is (1-s) x[a0] + s x[a1].")
      .def_property_readonly("t", [](py::object self) {
        const auto& r = self.cast<const EeView&>().set->ee;
        return column<double>(r, r.empty() ? nullptr : &r[0].t, {}, {}, self);
      }, "(k,) float64: closest point on b is (1-t) x[b0] + t x[b1].")
      .def_property_readonly("distance", [](py::object self) {
        const auto& r = self.cast<const EeView&>().set->ee;
        return column<double>(r, r.empty() ? nullptr : &r[0].distance, {}, {}, self);
      }, "(k,) float64 distance between the edges (< thickness).")
      .def_property_readonly("normal", [](py::object self) {
        const auto& r = self.cast<const EeView&>().set->ee;
        return column<double>(r, r.empty() ? nullptr : r[0].normal.data(), {3}, {8}, self);
      }, "(k, 3) float64 unit vector from the closest point on a towards the one on b.");

  py::class_<TtView>(m, "TriangleTriangleContacts", R"doc(
Intersecting face pairs (sharing no vertex) of one result, in canonical order; read-only view
over the library's records (no copy).
)doc")
      .def("__len__", [](const TtView& v) { return v.set->tt.size(); })
      .def_property_readonly("faces", [](py::object self) {
        const auto& r = self.cast<const TtView&>().set->tt;
        const py::ssize_t step = r.empty() ? 4 : gap(&r[0].face0, &r[0].face1);
        return column<Index>(r, r.empty() ? nullptr : &r[0].face0, {2}, {step}, self);
      }, "(k, 2) int32 face ids, face0 < face1.");

  py::class_<PyContacts>(m, "Contacts", R"doc(
The contacts of one `Detector.update`, sorted canonically. `vf`, `ee` and `tt` give NumPy
views over the records the library filled (no element is copied); a `Contacts` and its arrays
stay valid after later updates (the detector then fills a new buffer).
)doc")
      .def_property_readonly("vf", [](const PyContacts& c) { return VfView{c.set}; })
      .def_property_readonly("ee", [](const PyContacts& c) { return EeView{c.set}; })
      .def_property_readonly("tt", [](const PyContacts& c) { return TtView{c.set}; })
      .def("__len__", [](const PyContacts& c) { return c.set->size(); })
      .def(
          "write", [](const PyContacts& c, const std::filesystem::path& path) {
            write_contacts_file(path, *c.set);
          },
          py::arg("path"),
          "Writes the CLI's `--contacts` text format ('vf V F d', 'ee A0 A1 B0 B1 d', 'tt F0 F1').")
      .def("__repr__", [](const PyContacts& c) {
        return "Contacts(vf=" + std::to_string(c.set->vf.size()) + ", ee=" +
               std::to_string(c.set->ee.size()) + ", tt=" + std::to_string(c.set->tt.size()) + ")";
      });

  py::class_<PyDetector>(m, "Detector", R"doc(
A self-collision detector: `set_topology(mesh)` once, then `update(positions)` or
`update(previous, positions)` every frame. Contact with thickness h: vertex-face or edge-edge
pairs sharing no vertex closer than h; tt: faces sharing no vertex that intersect.
)doc")
      .def(py::init<const std::string&, double, const std::string&, int>(), py::arg("method") = "kdop",
           py::kw_only(), py::arg("thickness"), py::arg("kinds") = "vf,ee", py::arg("threads") = 0,
           R"doc(
method: a spec NAME[:key=value,...] exactly as the CLI's --method (see crumple.methods()).
thickness: h >= 0 in scene units (crumple.default_thickness(positions) gives the CLI's default).
kinds: comma-separated vf, ee, tt.
threads: worker threads, 0 = all hardware threads, 1 = serial.
Raises crumple.InputError (a ValueError) on a bad spec, key, value, kinds or thickness.
)doc")
      .def("set_topology", &PyDetector::set_topology, py::arg("mesh"),
           "Sets the connectivity (keeps the mesh's topology alive); resets all frame state.")
      .def(
          "update",
          [](PyDetector& d, py::object positions) { return d.update(py::none(), positions); },
          py::arg("positions"))
      .def("update", &PyDetector::update, py::arg("previous"), py::arg("positions"), R"doc(
Detects the contacts at positions, an (n, 3) real array with n = the topology's vertex count.
previous: the last frame's positions, for methods that use motion (others ignore them).
A float64 C-contiguous array is read in place. float32 arrays and rows at a stride (e.g.
buffer[:, 0:3] of an interleaved (n, 8) vertex buffer) are read in place too and converted
to float64 once inside the detector; other dtypes and layouts are copied once first (see
last_positions_conversion). The GIL is released while detecting.
Raises ValueError on a wrong shape or count, crumple.InputError on non-finite coordinates,
RuntimeError before set_topology. Returns a Contacts.
)doc")
      .def_property_readonly("stats", [](PyDetector& d) {
        const auto lock = d.guard();
        py::dict out;
        for (const auto& [key, value] : d.detector().stats().items()) out[py::str(key)] = value;
        return out;
      }, "Counters of the last update (the CLI's --json 'stats'), dict str -> float.")
      .def_property_readonly(
          "last_positions_copied",
          [](const PyDetector& d) { return std::string(d.last_conversion()) != "none"; },
          "Whether the last update's positions were converted to float64 rather than read in place "
          "(see last_positions_conversion).")
      .def_property_readonly(
          "last_positions_conversion", [](const PyDetector& d) { return std::string(d.last_conversion()); },
          "Where the last update's positions became float64: 'none' (a packed float64 array read in "
          "place), 'detector' (float32, or float64 rows at a stride: read in place and converted "
          "once inside the detector, no copy made by the binding), 'binding' (other dtypes, "
          "Fortran order, sequences: one copy made first).")
      .def_property_readonly(
          "last_update_ms", [](const PyDetector& d) { return d.last_update_ms(); },
          "Wall time (ms) of the last update's library call alone, as the CLI's detect --json "
          "'ms' (the binding's own work, argument checks and result wrapping, excluded).")
      .def_property_readonly("method", [](const PyDetector& d) { return d.spec().to_string(); },
                             "The canonical method spec.")
      .def_property_readonly("thickness", [](const PyDetector& d) { return d.detector().options().thickness; })
      .def_property_readonly("kinds", [](const PyDetector& d) { return d.detector().options().kinds.to_string(); })
      .def_property_readonly("threads", [](const PyDetector& d) { return d.detector().options().threads; })
      .def_property_readonly("capabilities", [](const PyDetector& d) {
        return capabilities_dict(d.detector().capabilities());
      }, "dict: exact, stochastic, uses_motion.")
      .def("save_state", [](PyDetector& d) {
             const auto lock = d.guard();
             return d.detector().save_state();
           },
           "The state carried across frames (before the last update) as one line of text; empty "
           "for exact methods.")
      .def(
          "load_state",
          [](PyDetector& d, const std::string& text) {
            const auto lock = d.guard();
            if (!d.has_topology()) throw std::runtime_error("Detector.load_state: call set_topology(mesh) first");
            d.detector().load_state(text);
          },
          py::arg("text"), "Restores a save_state text; crumple.InputError if it does not fit.");

  m.def("methods", [] {
    py::list out;
    for (const MethodInfo& info : all_methods()) {
      py::dict d;
      d["name"] = std::string(info.name);
      d["summary"] = std::string(info.summary);
      d["capabilities"] = capabilities_dict(info.capabilities);
      py::dict params;
      for (const ParamInfo& p : info.params) {
        params[py::str(std::string(p.key))] =
            py::make_tuple(std::string(p.default_value), std::string(p.description));
      }
      d["params"] = params;
      out.append(d);
    }
    return out;
  }, "Every detection method: list of dicts name, summary, capabilities, params {key: (default, description)}.");
}

}  // namespace crumple::python
