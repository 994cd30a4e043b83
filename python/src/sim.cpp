/// `crumple.Simulation`, `crumple.scenes` and `crumple.render`: the simulator and the software
/// rasteriser from Python. Thin on purpose: scene options travel in the scene spec text (the
/// CLI's `simulate SPEC`), run settings as the CLI's option names.

#include "bindings.hpp"

#include <crumple/mesh/mesh.hpp>
#include <crumple/render/camera.hpp>
#include <crumple/render/colouring.hpp>
#include <crumple/render/picture.hpp>
#include <crumple/sim/scene.hpp>
#include <crumple/sim/simulation.hpp>
#include <crumple/sim/time_step.hpp>

#include <pybind11/stl.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace crumple::python {

namespace {

/// Run settings given from Python; unset ones keep the scene's suggestion.
struct SettingsArgs {
  std::optional<std::string> method;
  std::optional<double> thickness;
  std::optional<std::string> kinds;
  std::optional<bool> response;
  std::optional<bool> fail_safe;
  std::optional<bool> untangle;
  std::optional<std::string> untangle_pull;
  std::optional<bool> motion_search;
  std::optional<int> motion_retries;
  std::optional<double> push_relaxation;
  std::optional<std::int64_t> response_from;
  std::optional<int> passes;
  std::optional<double> dt;
  std::optional<int> substeps;
  std::optional<std::string> integrator;
  int threads = 0;

  void apply(sim::Settings& s) const {
    if (method) s.method = MethodSpec::parse(*method);
    if (thickness) s.detector.thickness = *thickness;
    if (kinds) s.detector.kinds = ContactKinds::parse(*kinds);
    if (response) s.response = *response;
    if (fail_safe) s.fail_safe = *fail_safe;
    if (untangle) s.untangle = *untangle;
    if (untangle_pull) {
      if (*untangle_pull != "after" && *untangle_pull != "solve") {
        throw InputError("Simulation: untangle_pull must be \"after\" or \"solve\", not \"" + *untangle_pull + "\"");
      }
      s.untangle_in_solve = *untangle_pull == "solve";
    }
    if (motion_search) s.motion_search = *motion_search;
    if (motion_retries) s.motion_retries = *motion_retries;
    if (push_relaxation) s.proximity_relaxation = *push_relaxation;
    if (passes) s.passes = *passes;
    if (dt) s.dt = *dt;
    if (substeps) s.substeps = *substeps;
    if (integrator) s.integrator = sim::parse_integrator(*integrator);
    s.detector.threads = threads;
    if (!(s.dt > 0 && std::isfinite(s.dt))) throw InputError("Simulation: dt must be > 0");
    if (s.substeps < 1) throw InputError("Simulation: substeps must be >= 1");
    if (s.passes < 1) throw InputError("Simulation: passes must be >= 1");
    if (s.motion_retries < 0) throw InputError("Simulation: motion_retries must be >= 0");
    if (!(s.proximity_relaxation > 0 && s.proximity_relaxation <= 1)) {
      throw InputError("Simulation: push_relaxation must be in (0, 1]");
    }
    if (!(s.detector.thickness >= 0 && std::isfinite(s.detector.thickness))) {
      throw InputError("Simulation: thickness must be finite and >= 0");
    }
    if (threads < 0) throw InputError("Simulation: threads must be >= 0");
    if (response_from) {
      if (*response_from < 0) throw InputError("Simulation: response_from must be >= 0 (a frame)");
      if (response && !*response) {
        throw InputError("Simulation: response_from needs the response on, not response=False");
      }
      s.response = true;
    }
  }
  /// Whether the user chose the step (then `sim::fit_time_step` keeps it).
  bool user_step() const { return dt.has_value() || substeps.has_value(); }
};

/// Camera and drawing options of a picture.
struct PictureArgs {
  int width = 640;
  int height = 480;
  double yaw = 30;
  double pitch = 20;
  std::optional<double> distance;
  bool wireframe = false;
  bool springs = false;
  bool contacts = true;
  int supersample = 2;

  void check() const {
    if (width < 1 || height < 1 || width > 16384 || height > 16384) {
      throw InputError("render: width and height must be in 1..16384");
    }
    if (supersample < 1 || supersample > 4) throw InputError("render: supersample must be 1..4");
    if (!(pitch >= -89 && pitch <= 89)) throw InputError("render: pitch must be in [-89, 89] degrees");
    if (!std::isfinite(yaw)) throw InputError("render: yaw must be finite");
    if (distance && !(*distance > 0 && std::isfinite(*distance))) {
      throw InputError("render: distance must be > 0");
    }
  }
  render::Camera camera(PositionsView x) const {
    render::Camera cam;
    cam.yaw_deg = yaw;
    cam.pitch_deg = pitch;
    cam.fit(compute_bounds(x), static_cast<double>(width) / height);
    if (distance) cam.distance = *distance;
    return cam;
  }
  render::DrawOptions options() const {
    render::DrawOptions o;
    o.wireframe = wireframe;
    o.masses_springs = springs;
    o.colliding_edges = contacts;
    o.contact_segments = contacts;
    return o;
  }
};

/// The picture's pixels as a new (h, w, 3) uint8 array that owns them (moved, not copied).
py::array picture_array(render::Picture&& picture) {
  auto* bytes = new std::vector<std::uint8_t>(std::move(picture.data()));
  py::capsule owner(bytes, [](void* p) { delete static_cast<std::vector<std::uint8_t>*>(p); });
  const py::ssize_t h = picture.height(), w = picture.width();
  return py::array(py::dtype::of<std::uint8_t>(), {h, w, py::ssize_t{3}}, {3 * w, py::ssize_t{3}, py::ssize_t{1}},
                   bytes->data(), owner);
}

py::dict stats_dict(const sim::FrameStats& s) {
  py::dict d;
  d["frame"] = s.frame;
  d["time"] = s.time;
  d["integrate_ms"] = s.integrate_ms;
  d["detect_ms"] = s.detect_ms;
  d["response_ms"] = s.response_ms;
  d["ccd_ms"] = s.ccd_ms;
  d["ccd_impacts"] = s.ccd_impacts;
  d["ccd_queries"] = s.ccd_queries;
  d["ccd_zone_vertices"] = s.ccd_zone_vertices;
  d["ccd_frozen"] = s.ccd_frozen;
  d["ccd_first_restricted"] = s.ccd_first_restricted;
  d["motion_pairs"] = s.motion_pairs;
  d["motion_vertices"] = s.motion_vertices;
  d["proximity_pairs"] = s.proximity_pairs;
  d["flat_pairs"] = s.flat_pairs;
  d["retries"] = s.retries;
  d["vf"] = s.vf;
  d["ee"] = s.ee;
  d["tt"] = s.tt;
  d["collision_share"] = s.collision_share;
  d["min_distance"] = s.min_distance;
  d["obstacle_penetration"] = s.obstacle_penetration;
  d["cg_iterations"] = s.cg_iterations;
  d["corrections"] = s.corrections;
  d["energy"] = s.energy;
  d["max_speed"] = s.max_speed;
  d["longest_spring"] = s.longest_spring;
  d["intersecting_pairs"] = s.intersecting_pairs;
  d["pinches"] = s.pinches;
  d["contours"] = s.contours;
  d["untangle_pulls"] = s.untangle_pulls;
  d["untangle_ms"] = s.untangle_ms;
  return d;
}

/// Per-frame figures as columns: every key of `stats_dict` → (frames,) array, plus
/// bounds_min / bounds_max (frames, 3).
py::dict stats_columns(const std::vector<sim::FrameStats>& frames) {
  py::dict out;
  // Column dtypes follow the values' types (bool, int or float).
  const py::dict first = stats_dict(frames.empty() ? sim::FrameStats{} : frames.front());
  std::vector<py::list> columns(first.size());
  for (const sim::FrameStats& f : frames) {
    std::size_t k = 0;
    for (auto item : stats_dict(f)) columns[k++].append(item.second);
  }
  const py::object asarray = py::module_::import("numpy").attr("asarray");
  std::size_t k = 0;
  for (auto item : first) {
    const char* dtype = py::isinstance<py::bool_>(item.second)    ? "bool"
                        : py::isinstance<py::float_>(item.second) ? "float64"
                                                                  : "int64";
    out[item.first] = asarray(columns[k++], dtype);
  }
  py::array_t<double> lo({static_cast<py::ssize_t>(frames.size()), py::ssize_t{3}});
  py::array_t<double> hi({static_cast<py::ssize_t>(frames.size()), py::ssize_t{3}});
  auto l = lo.mutable_unchecked<2>();
  auto h = hi.mutable_unchecked<2>();
  for (std::size_t i = 0; i < frames.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      l(static_cast<py::ssize_t>(i), c) = frames[i].bounds.min[c];
      h(static_cast<py::ssize_t>(i), c) = frames[i].bounds.max[c];
    }
  }
  out["bounds_min"] = lo;
  out["bounds_max"] = hi;
  return out;
}

/// (n, 3) float64 array holding a copy of `x` (the simulation rewrites its own).
py::array_t<double> positions_copy(PositionsView x) {
  py::array_t<double> out({static_cast<py::ssize_t>(x.size()), py::ssize_t{3}});
  double* dst = out.mutable_data();
  for (std::size_t i = 0; i < x.size(); ++i) {
    for (int c = 0; c < 3; ++c) dst[3 * i + static_cast<std::size_t>(c)] = x[i][c];
  }
  return out;
}

/// The Python simulation: one `sim::Simulation` and a guard against concurrent use while the
/// GIL is released.
class PySimulation {
 public:
  PySimulation(sim::Scene scene, const SettingsArgs& args, std::uint64_t seed) : seed_(seed) {
    spec_ = scene.spec;
    edge_length_ = scene.edge_length;
    sim::Settings settings = scene.settings;
    args.apply(settings);
    fit_ = sim::fit_time_step(settings, scene.model, scene.field, scene.state.x, args.user_step());
    topology_ = scene.model.topology_ptr();
    // response_from: the run starts with the response off and switches to `settings` there.
    if (args.response_from && *args.response_from > 0) response_from_ = *args.response_from;
    settings_ = settings;
    kinematics_ = scene.kinematics;
    sim::Settings early = settings;
    early.response = false;
    sim_ = std::make_unique<sim::Simulation>(std::move(scene.model), std::move(scene.state), scene.field,
                                             std::move(scene.obstacles), std::move(scene.kinematics),
                                             response_from_ ? early : settings);
  }

  /// Warns (RuntimeWarning) when the step was kept beyond the integrator's stable range, as the
  /// CLI does; call with the GIL held.
  void warn_unstable_step() const {
    if (fit_.action != sim::StepFit::Kept) return;
    char text[512];
    std::snprintf(text, sizeof text,
                  "crumple.Simulation: the time step %.3g s is beyond %s's stable range (about %.3g s for "
                  "the model's fastest modes): the run will likely diverge. Use dt=%.3g, substeps=%d (same "
                  "frame length) or integrator='implicit-euler'",
                  fit_.given_dt, std::string(sim::to_string(settings_.integrator)).c_str(), fit_.stable_dt,
                  fit_.dt, fit_.substeps);
    if (PyErr_WarnEx(PyExc_RuntimeWarning, text, 1) != 0) throw py::error_already_set();
  }

  std::unique_lock<std::mutex> guard() {
    std::unique_lock lock(busy_, std::try_to_lock);
    if (!lock) throw std::runtime_error("Simulation is in use by another thread");
    return lock;
  }

  std::vector<sim::FrameStats> run(std::int64_t frames) {
    if (frames < 0) throw py::value_error("Simulation.run: frames must be >= 0");
    const auto lock = guard();
    std::vector<sim::FrameStats> out;
    out.reserve(static_cast<std::size_t>(frames));
    py::gil_scoped_release release;
    for (std::int64_t f = 0; f < frames; ++f) {
      if (response_from_ && sim_->frame() == *response_from_) {
        // The response starts: a new simulation from the current state with the full settings.
        sim::Simulation& before = *sim_;
        sim_ = std::make_unique<sim::Simulation>(before.model(), before.state(), before.field(), before.obstacles(),
                                                 kinematics_, settings_, before.frame());
        response_from_.reset();
      }
      out.push_back(sim_->advance_frame());
    }
    return out;
  }

  py::array render(const PictureArgs& args) {
    args.check();
    const auto lock = guard();
    render::Picture picture;
    {
      py::gil_scoped_release release;
      const PositionsView x = sim_->state().x;
      std::vector<Edge> springs;
      for (const sim::Spring& s : sim_->model().springs()) springs.push_back({s.a, s.b});
      const auto n = static_cast<std::size_t>(sim_->model().num_particles());
      std::unique_ptr<bool[]> pinned(new bool[n]);
      for (std::size_t i = 0; i < n; ++i) pinned[i] = sim_->model().pinned(static_cast<Index>(i));
      const std::vector<render::ShapeMesh> obstacles =
          render::obstacle_meshes(sim_->obstacles(), sim_->state().time, x);
      const render::Frame frame{topology_.get(), x, &sim_->contacts(), springs,
                                std::span<const bool>(pinned.get(), n), obstacles};
      picture = render::render_frame(frame, args.camera(x), args.width, args.height, args.options(),
                                     args.supersample);
    }
    return picture_array(std::move(picture));
  }

  sim::Simulation& sim() { return *sim_; }
  const std::shared_ptr<const Topology>& topology() const { return topology_; }
  const std::string& spec() const { return spec_; }
  std::uint64_t seed() const { return seed_; }
  double edge_length() const { return edge_length_; }
  const sim::TimeStepFit& time_step_fit() const { return fit_; }
  /// The frame from which the response is on, while it is still ahead.
  const std::optional<std::int64_t>& response_from() const { return response_from_; }

 private:
  std::string spec_;
  std::uint64_t seed_;
  double edge_length_ = 0;
  std::shared_ptr<const Topology> topology_;
  std::unique_ptr<sim::Simulation> sim_;
  sim::Settings settings_;  ///< the run's settings (response on from `response_from_`)
  sim::Kinematics kinematics_;
  std::optional<std::int64_t> response_from_;
  sim::TimeStepFit fit_;
  std::mutex busy_;
};

SettingsArgs settings_args(const py::kwargs& kw) {
  SettingsArgs a;
  for (auto item : kw) {
    const std::string key = py::str(item.first);
    const py::handle v = item.second;
    if (v.is_none()) continue;
    if (key == "method") a.method = v.cast<std::string>();
    else if (key == "thickness") a.thickness = v.cast<double>();
    else if (key == "kinds") a.kinds = v.cast<std::string>();
    else if (key == "response") a.response = v.cast<bool>();
    else if (key == "fail_safe") a.fail_safe = v.cast<bool>();
    else if (key == "untangle") a.untangle = v.cast<bool>();
    else if (key == "untangle_pull") a.untangle_pull = v.cast<std::string>();
    else if (key == "motion_search") a.motion_search = v.cast<bool>();
    else if (key == "motion_retries") a.motion_retries = v.cast<int>();
    else if (key == "push_relaxation") a.push_relaxation = v.cast<double>();
    else if (key == "response_from") a.response_from = v.cast<std::int64_t>();
    else if (key == "passes") a.passes = v.cast<int>();
    else if (key == "dt") a.dt = v.cast<double>();
    else if (key == "substeps") a.substeps = v.cast<int>();
    else if (key == "integrator") a.integrator = v.cast<std::string>();
    else if (key == "threads") a.threads = v.cast<int>();
    else {
      throw py::type_error("Simulation: unexpected keyword '" + key +
                           "' (method, thickness, kinds, response, fail_safe, untangle, untangle_pull, motion_search, "
                           "motion_retries, "
                           "push_relaxation, response_from, passes, dt, "
                           "substeps, integrator, threads; scene options go in the spec text)");
    }
  }
  return a;
}

PictureArgs picture_args(int width, int height, double yaw, double pitch, std::optional<double> distance,
                         bool wireframe, bool springs, bool contacts, int supersample) {
  return PictureArgs{width, height, yaw, pitch, distance, wireframe, springs, contacts, supersample};
}

constexpr const char* kSettingsDoc = R"doc(
Run settings (keyword-only; None or absent keeps the scene's suggestion, the CLI's options):
method (detection spec, as Detector's), thickness (contact thickness, m), kinds ("vf,ee"),
response (bool: self-collision response), fail_safe (bool, default on with response: the
continuous fail-safe that keeps every frame intersection-free, docs/simulation.md), untangle
(bool, default on with response: a cloth that already intersects itself is untangled; the
figures intersecting_pairs, contours and untangle_pulls), untangle_pull ("after", the default:
the pulls move the vertices after each step; "solve": inside the implicit Euler step, as the
CLI's --untangle-pull), motion_search (bool: pairs the
velocities bring within the thickness join the frame's contacts), motion_retries (int >= 0: times
a frame may run again when its own motion brings far pairs within the fail-safe's reach; the
crumple scene uses 1), push_relaxation (the share in (0, 1] of a pair's shortfall below the
thickness each push-out closes; the crumple scene uses 0.5), response_from (frame from which the
response is on, off before it, as the CLI's --response-from), passes (>= 1), dt (step, s),
substeps (steps per frame), integrator ("implicit-euler", "explicit-euler",
"symplectic-euler", "rk4", "projective"), threads (0 = all).
Time step as the CLI's: the scene's own step beyond an explicit integrator's stable range is
split into stable substeps of the same frame length (see time_step_fit); a dt or substeps
given here is kept, with a RuntimeWarning when beyond that range.
Raises crumple.InputError (a ValueError) on a bad spec, key or value, TypeError on an unknown
keyword.
)doc";

}  // namespace

void bind_sim(py::module_& m) {
  py::class_<PySimulation> cls(m, "Simulation", R"doc(
A cloth simulation (mass-spring cloth, obstacles, self-collision detection and response), as the
CLI's `simulate`: `Simulation("cloth-on-sphere:n=32")` builds a built-in scene,
`Simulation.from_mesh(mesh, "pins=0;1")` a cloth from a mesh (e.g. TriMesh(vertices, faces)).
`advance()` runs one frame, `run(frames)` several; the GIL is released while stepping.
Deterministic: the same spec, seed and settings give the same positions, bit for bit.
)doc");
  cls.def(py::init([](const std::string& scene, std::uint64_t seed, const py::kwargs& kw) {
            const SettingsArgs args = settings_args(kw);
            auto out = std::make_unique<PySimulation>(sim::make_scene(sim::SceneSpec::parse(scene), seed), args,
                                                      seed);
            out->warn_unstable_step();
            return out;
          }),
          py::arg("scene") = "cloth-on-sphere", py::kw_only(), py::arg("seed") = 1,
          (std::string(R"doc(
scene: a built-in scene spec NAME[:key=value,...] exactly as the CLI's `simulate SPEC` (see
crumple.scenes()). seed: the scene's random perturbation.
)doc") + kSettingsDoc).c_str())
      .def_static(
          "from_mesh",
          [](const TriMesh& mesh, const std::string& params, const py::kwargs& kw) {
            const SettingsArgs args = settings_args(kw);
            const std::string spec = params.empty() ? std::string("file") : "file:" + params;
            auto out = std::make_unique<PySimulation>(
                sim::make_scene_from_mesh(mesh, sim::SceneSpec::parse(spec)), args, 0);
            out->warn_unstable_step();
            return out;
          },
          py::arg("mesh"), py::arg("params") = "",
          (std::string(R"doc(
A cloth made of a mesh (its positions are the rest and initial state). params: the `file`
scene's keys as "key=value,...", e.g. "pins=0;7,stiffness=500" (see crumple.scenes()).
)doc") + kSettingsDoc).c_str())
      .def(
          "advance",
          [](PySimulation& s) { return stats_dict(s.run(1).front()); },
          "Runs one frame (substeps steps, then detection); returns its figures (dict, see "
          "current_stats). crumple.DivergenceError if a step diverges (the simulation is then "
          "back at the frame's start).")
      .def(
          "run", [](PySimulation& s, std::int64_t frames) { return stats_columns(s.run(frames)); },
          py::arg("frames"), R"doc(
Runs `frames` frames; returns their figures as columns: each key of current_stats -> (frames,)
array (int64 counts, float64 figures), plus bounds_min and bounds_max (frames, 3) float64.
On divergence raises crumple.DivergenceError; the frames before it stay done.
)doc")
      .def(
          "current_stats",
          [](PySimulation& s) {
            const auto lock = s.guard();
            return stats_dict(s.sim().current_stats());
          },
          "Figures of the current frame: frame, time (s), integrate_ms, detect_ms, response_ms, "
          "ccd_ms, ccd_impacts, ccd_queries, ccd_zone_vertices, ccd_frozen, ccd_first_restricted (the fail-safe; "
          "the last: its first query covered only the pairs the frame's start detection could not rule out), "
          "motion_pairs, motion_vertices (motion search), proximity_pairs (the frame's proximity stencils), "
          "flat_pairs (pairs of one flat patch left out beyond 2 h_c), retries (times the frame ran again: "
          "its own motion brought far pairs within the fail-safe's reach), vf, ee, tt (contacts), collision_share (edges in contact, 0..1), min_distance, "
          "obstacle_penetration (m), cg_iterations, corrections, energy (J), max_speed (m/s), "
          "longest_spring (the longest spring over its rest length), "
          "intersecting_pairs (intersecting triangle pairs at the frame's end, -1 when not measured: "
          "response or untangle off), pinches (intersecting pairs sharing one vertex, likewise), "
          "contours (intersection contours), untangle_pulls (the "
          "untangler's pushes over the frame's steps), untangle_ms.")
      .def_property_readonly(
          "positions",
          [](PySimulation& s) {
            const auto lock = s.guard();
            return positions_copy(s.sim().state().x);
          },
          "(n, 3) float64 copy of the current positions (the simulation rewrites its own).")
      .def_property_readonly(
          "velocities",
          [](PySimulation& s) {
            const auto lock = s.guard();
            return positions_copy(s.sim().state().v);
          },
          "(n, 3) float64 copy of the current velocities.")
      .def_property_readonly(
          "faces",
          [](py::object self) {
            const Topology& t = *self.cast<PySimulation&>().topology();
            static const Face kEmpty{};
            const auto m = static_cast<py::ssize_t>(t.num_faces());
            return readonly_view<Index>(m > 0 ? t.faces().front().data() : kEmpty.data(), {m, 3},
                                        {static_cast<py::ssize_t>(sizeof(Face)), sizeof(Index)}, self);
          },
          "(m, 3) int32 read-only view of the cloth's faces.")
      .def_property_readonly(
          "pinned",
          [](PySimulation& s) {
            const sim::Model& model = s.sim().model();
            py::array_t<bool> out(model.num_particles());
            auto o = out.mutable_unchecked<1>();
            for (Index i = 0; i < model.num_particles(); ++i) o(i) = model.pinned(i);
            return out;
          },
          "(n,) bool: particles driven by the scene (pinned), not integrated.")
      .def(
          "mesh",
          [](PySimulation& s) {
            const auto lock = s.guard();
            const Topology& t = *s.topology();
            return TriMesh::create(s.sim().state().x, std::vector<Face>(t.faces().begin(), t.faces().end()));
          },
          "A TriMesh of the current positions (e.g. for Detector.set_topology or write_mesh).")
      .def(
          "contacts",
          [](PySimulation& s) {
            const auto lock = s.guard();
            py::gil_scoped_release release;
            return PyContacts{std::make_shared<const ContactSet>(s.sim().contacts())};
          },
          "The self-contacts at the current positions (a Contacts, with the simulation's detector "
          "and thickness).")
      .def(
          "render",
          [](PySimulation& s, int width, int height, double yaw, double pitch, std::optional<double> distance,
             bool wireframe, bool springs, bool contacts, int supersample) {
            return s.render(picture_args(width, height, yaw, pitch, distance, wireframe, springs, contacts,
                                         supersample));
          },
          py::arg("width") = 640, py::arg("height") = 480, py::kw_only(), py::arg("yaw") = 30.0,
          py::arg("pitch") = 20.0, py::arg("distance") = py::none(), py::arg("wireframe") = false,
          py::arg("springs") = false, py::arg("contacts") = true, py::arg("supersample") = 2, R"doc(
The current frame as the CLI's `render` draws it: an (height, width, 3) uint8 RGB array, rows
top to bottom. Camera: yaw and pitch in degrees (pitch within [-89, 89]), distance None = fit
the cloth. wireframe draws the edges; springs the masses and springs instead of the surface;
contacts the edges in collision in red and the VF contacts as segments. supersample 1..4.
The GIL is released while drawing. crumple.InputError on a bad size or camera.
)doc")
      .def_property_readonly(
          "time",
          [](PySimulation& s) {
            const auto lock = s.guard();
            return s.sim().state().time;
          },
          "Simulated time (s).")
      .def_property_readonly(
          "frame",
          [](PySimulation& s) {
            const auto lock = s.guard();
            return s.sim().frame();
          },
          "Current frame number (0 = the initial state).")
      .def_property_readonly("num_vertices", [](PySimulation& s) { return s.sim().model().num_particles(); })
      .def_property_readonly("scene", &PySimulation::spec, "The canonical scene spec.")
      .def_property_readonly("seed", &PySimulation::seed)
      .def_property_readonly("edge_length", &PySimulation::edge_length, "Mean rest length of the edges (m).")
      .def_property_readonly(
          "settings",
          [](PySimulation& s) {
            const sim::Settings& st = s.sim().settings();
            py::dict d;
            d["dt"] = st.dt;
            d["substeps"] = st.substeps;
            d["integrator"] = std::string(sim::to_string(st.integrator));
            d["method"] = st.method.to_string();
            d["thickness"] = st.detector.thickness;
            d["kinds"] = st.detector.kinds.to_string();
            d["response"] = st.response;
            d["fail_safe"] = st.fail_safe;
            d["untangle"] = st.untangle;
            d["untangle_pull"] = std::string(st.untangle_in_solve ? "solve" : "after");
            d["motion_search"] = st.motion_search;
            d["motion_retries"] = st.motion_retries;
            d["push_relaxation"] = st.proximity_relaxation;
            d["response_from"] = s.response_from() ? py::object(py::int_(*s.response_from())) : py::object(py::none());
            d["passes"] = st.passes;
            d["threads"] = st.detector.threads;
            return d;
          },
          "The run settings in use (dict with the constructor's keyword names; response is off and "
          "response_from the frame number until the run reaches response_from, then None).")
      .def_property_readonly(
          "time_step_fit",
          [](PySimulation& s) {
            const sim::TimeStepFit& f = s.time_step_fit();
            py::dict d;
            d["action"] = f.action == sim::StepFit::Split ? "split" : f.action == sim::StepFit::Kept ? "kept" : "stable";
            d["stable_dt"] = f.stable_dt;
            d["given_dt"] = f.given_dt;
            d["given_substeps"] = f.given_substeps;
            d["dt"] = f.dt;
            d["substeps"] = f.substeps;
            return d;
          },
          "How the step was fitted to the integrator's stable range (the CLI's rule): action "
          "'stable' (within it), 'split' (the scene's own step split into substeps of the same "
          "frame length), 'kept' (a dt or substeps given beyond it, kept: likely to diverge); "
          "stable_dt (s, inf for implicit integrators), given_dt, given_substeps, and dt, "
          "substeps: the stable split (applied when 'split').")
      .def_property_readonly(
          "detector_stats",
          [](PySimulation& s) {
            const auto lock = s.guard();
            py::dict out;
            for (const auto& [key, value] : s.sim().detector().stats().items()) out[py::str(key)] = value;
            return out;
          },
          "Counters of the simulation detector's last update (as Detector.stats).")
      .def("__repr__", [](PySimulation& s) {
        const auto lock = s.guard();
        return "Simulation('" + s.spec() + "', frame=" + std::to_string(s.sim().frame()) + ")";
      });

  m.def("scenes", [] {
    py::list out;
    for (const sim::SceneInfo& info : sim::all_scenes()) {
      py::dict d;
      d["name"] = std::string(info.name);
      d["summary"] = std::string(info.summary);
      py::dict params;
      for (const sim::SceneParamInfo& p : info.params) {
        params[py::str(std::string(p.key))] =
            py::make_tuple(std::string(p.default_value), std::string(p.description));
      }
      d["params"] = params;
      out.append(d);
    }
    return out;
  }, "Every scene: list of dicts name, summary, params {key: (default, description)}; the last, "
     "'file', lists the keys of Simulation.from_mesh.");

  m.def(
      "render",
      [](const TriMesh& mesh, py::handle positions, std::optional<PyContacts> contacts, int width, int height,
         double yaw, double pitch, std::optional<double> distance, bool wireframe, int supersample) {
        const PictureArgs args = picture_args(width, height, yaw, pitch, distance, wireframe, false, true,
                                              supersample);
        args.check();
        PositionsArg arg;
        PositionsView x = mesh.positions();
        if (!positions.is_none()) {
          arg = positions_arg(positions, "positions");
          x = arg.doubles();
          if (x.size() != static_cast<std::size_t>(mesh.num_vertices())) {
            throw py::value_error("render: positions have " + std::to_string(x.size()) +
                                  " rows, the mesh " + std::to_string(mesh.num_vertices()) + " vertices");
          }
        }
        render::Picture picture;
        {
          py::gil_scoped_release release;
          check_finite(x);
          const render::Frame frame{&mesh.topology(), x, contacts ? contacts->set.get() : nullptr, {}, {}, {}};
          picture = render::render_frame(frame, args.camera(x), width, height, args.options(), supersample);
        }
        return picture_array(std::move(picture));
      },
      py::arg("mesh"), py::arg("positions") = py::none(), py::arg("contacts") = py::none(), py::arg("width") = 640,
      py::arg("height") = 480, py::kw_only(), py::arg("yaw") = 30.0, py::arg("pitch") = 20.0,
      py::arg("distance") = py::none(), py::arg("wireframe") = false, py::arg("supersample") = 2, R"doc(
Draws a mesh (at positions, an (n, 3) real array, or its own) with optional Contacts of those
positions (edges in collision in red, VF contacts as segments), as the CLI's `render FILE`.
Returns a new (height, width, 3) uint8 RGB array. The GIL is released while drawing.
)doc");
}

}  // namespace crumple::python
