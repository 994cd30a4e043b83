// crumple-view: interactive viewer. Opens a built-in scene, a mesh / MassSpring file or a
// folder of frames; runs the simulation live (library: sim::Simulation, make_detector) and
// draws it with the colouring of crumple::render: shaded surface lit on both sides, edges in
// collision in red, vertex-face contacts as segments. No algorithm lives here: it parses,
// calls the library and draws.
//
// Automation: `crumple-view [INPUT] --frames N --screenshot out.png --exit` steps N frames,
// draws one frame, saves the GL framebuffer (glReadPixels) and exits.
#include "../cli/sim_glue.hpp"
#include "gl_draw.hpp"

#include <crumple/core/error.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/detect/stochastic.hpp>
#include <crumple/io/frames.hpp>
#include <crumple/io/mesh_io.hpp>
#include <crumple/io/x3d.hpp>
#include <crumple/render/picture.hpp>
#include <crumple/sim/scene.hpp>

#include <CLI/CLI.hpp>

#define GL_GLEXT_PROTOTYPES
#include <GL/gl.h>
#include <GL/glext.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace crumple::viewer {

namespace {

struct Options {
  std::string input = "hanging-cloth";
  std::vector<std::string> params;
  long long frames = 0;
  std::string screenshot;
  bool exit = false;
  std::string size = "1024x720";
  std::optional<std::string> method;
  std::optional<double> thickness;
  std::uint64_t seed = 1;
  bool wireframe = false;
  bool springs = false;
  bool active_pairs = false;
  int kdop_level = -1;
  bool recall = false;
};

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

bool is_mesh_file(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  return ext == ".obj" || ext == ".ply" || ext == ".off" || ext == ".x3d";
}

bool mentions(const std::filesystem::path& path, const std::string& needle) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str().find(needle) != std::string::npos;
}

constexpr std::array<const char*, 4> kVariants{"simple", "propagate-by-convergence", "direct",
                                               "vertex"};

/// Everything the viewer shows and steers.
class App {
 public:
  explicit App(Options options) : options_(std::move(options)) { load(); }

  // --- loading, reset, settings -------------------------------------------------------------
  void load() {
    const std::filesystem::path path(options_.input);
    const bool file =
        options_.input.find(':') == std::string::npos && std::filesystem::exists(path);
    sim_.reset();
    frames_.reset();
    if (file && std::filesystem::is_directory(path)) {
      std::vector<std::filesystem::path> files;
      for (const auto& e : std::filesystem::directory_iterator(path)) {
        if (e.is_regular_file() && is_mesh_file(e.path())) files.push_back(e.path());
      }
      std::sort(files.begin(), files.end());
      if (files.empty())
        throw InputError("folder '" + path.string() + "' holds no .obj .ply .off .x3d frame");
      frames_.emplace(std::move(files));
      settings_ = sim::Settings{};
      settings_.detector.thickness = 1e-3 * compute_bounds(frames_->first().positions()).diagonal();
      apply_overrides();
      frame_index_ = 0;
      set_playback_frame(0);
      source_ = "frames " + path.string();
      return;
    }
    if (!file && !path.extension().empty() && options_.input.find(':') == std::string::npos) {
      throw InputError("no such file, folder or scene: '" + options_.input + "'");
    }
    sim::SceneSpec spec = sim::SceneSpec::parse(file ? "file" : options_.input);
    for (const std::string& item : options_.params) {
      const auto eq = item.find('=');
      if (eq == std::string::npos)
        throw InputError("--param expects KEY=VALUE, got '" + item + "'");
      spec.set(item.substr(0, eq), item.substr(eq + 1));
    }
    if (!file) {
      scene_ = sim::make_scene(spec, options_.seed);
      source_ = "scene " + scene_.spec;
    } else if (io::format_from_path(path) == io::MeshFormat::X3d && mentions(path, "MassSpring")) {
      const io::MassSpringData data = io::read_mass_spring(path);
      scene_ = sim::make_scene_from_model(cli::model_from_mass_spring(data),
                                          cli::state_from_mass_spring(data, 0), spec);
      source_ = "mass-spring " + path.string();
    } else {
      scene_ = sim::make_scene_from_mesh(io::read_mesh(path), spec);
      source_ = "mesh " + path.string();
    }
    settings_ = scene_.settings;
    apply_overrides();
    reset();
  }

  void apply_overrides() {
    if (options_.method) settings_.method = MethodSpec::parse(*options_.method);
    if (options_.thickness) settings_.detector.thickness = *options_.thickness;
    options_.method.reset();
    options_.thickness.reset();
    sync_method_ui();
  }

  /// Back to the scene's initial state, with the current settings.
  void reset() {
    if (frames_) {
      frame_index_ = 0;
      set_playback_frame(0);
      return;
    }
    sim_.reset();
    sim_.emplace(scene_.model, scene_.state, scene_.field, scene_.obstacles, scene_.kinematics,
                 settings_);
    after_change();
    stats_ = sim_->current_stats();
  }

  /// Applies new settings, keeping the current state.
  void apply_settings(const sim::Settings& settings) {
    settings_ = settings;
    if (frames_) {
      after_change();
      set_playback_frame(frame_index_);
      return;
    }
    sim::Model model = sim_->model();
    sim::State state = sim_->state();
    sim::ForceField field = sim_->field();
    std::vector<response::Obstacle> obstacles = sim_->obstacles();
    const std::int64_t frame = sim_->frame();
    sim_.reset();
    sim_.emplace(std::move(model), std::move(state), field, std::move(obstacles), scene_.kinematics,
                 settings_, frame);
    after_change();
    stats_ = sim_->current_stats();
  }

  void after_change() {
    recall_.clear();
  }

  // --- stepping -----------------------------------------------------------------------------
  void advance() {
    if (frames_) {
      frame_index_ = (frame_index_ + 1) % frames_->size();
      set_playback_frame(frame_index_);
      return;
    }
    stats_ = sim_->advance_frame();
    recall_.clear();
  }

  void set_playback_frame(std::size_t i) {
    Positions x = frames_->positions(i);
    const auto t0 = std::chrono::steady_clock::now();
    if (!playback_detector_ || playback_spec_ != settings_.method.to_string() + "|" +
                                                     std::to_string(settings_.detector.thickness)) {
      playback_detector_ = make_detector(settings_.method, settings_.detector);
      playback_detector_->set_topology(frames_->first().topology_ptr());
      playback_spec_ =
          settings_.method.to_string() + "|" + std::to_string(settings_.detector.thickness);
      playback_x_.clear();
    }
    if (playback_x_.size() == x.size()) {
      playback_detector_->update(playback_x_, x, playback_contacts_);
    } else {
      playback_detector_->update(x, playback_contacts_);
    }
    stats_ = sim::FrameStats{};
    stats_.frame = static_cast<std::int64_t>(i);
    stats_.detect_ms = ms_since(t0);
    stats_.vf = playback_contacts_.vf.size();
    stats_.ee = playback_contacts_.ee.size();
    stats_.tt = playback_contacts_.tt.size();
    stats_.collision_share = sim::collision_share(topology(), playback_contacts_);
    playback_x_ = std::move(x);
    recall_.clear();
  }

  // --- accessors ----------------------------------------------------------------------------
  const Topology& topology() const {
    return frames_ ? frames_->first().topology() : sim_->model().topology();
  }
  PositionsView positions() const {
    return frames_ ? PositionsView(playback_x_) : PositionsView(sim_->state().x);
  }
  const ContactSet& contacts() { return frames_ ? playback_contacts_ : sim_->contacts(); }
  bool simulating() const { return sim_.has_value(); }
  sim::Simulation& simulation() { return *sim_; }

  // --- drawing ------------------------------------------------------------------------------
  void draw(GlDraw& gl, int width, int height) {
    gl.begin(camera, width, height, draw_options.palette);
    const Topology& topo = topology();
    const PositionsView x = positions();
    const render::Palette& pal = draw_options.palette;
    if (sim_) {  // the rigid obstacles, in one grey, where they are at the simulation's time
      render::Palette grey = pal;
      grey.front = grey.back = pal.obstacle;
      for (const render::ShapeMesh& m : render::obstacle_meshes(sim_->obstacles(), sim_->state().time, x)) {
        gl.surface(m.faces, m.positions, grey, lighting);
      }
    }
    Batch thin, thick;
    if (draw_options.masses_springs) {
      if (sim_) {
        for (const sim::Spring& s : sim_->model().springs()) {
          thin.line(x[static_cast<std::size_t>(s.a)], x[static_cast<std::size_t>(s.b)], pal.spring);
        }
        for (Index i = 0; i < sim_->model().num_particles(); ++i) {
          thin.point(x[static_cast<std::size_t>(i)],
                     sim_->model().pinned(i) ? pal.pinned : pal.mass);
        }
      } else {
        for (const Edge& e : topo.edges())
          thin.line(x[static_cast<std::size_t>(e[0])], x[static_cast<std::size_t>(e[1])],
                    pal.spring);
        for (const Vec3& p : x) thin.point(p, pal.mass);
      }
    } else {
      if (draw_options.surface) gl.surface(topo.faces(), x, pal, lighting);
      if (draw_options.wireframe || !draw_options.surface) {
        for (const Edge& e : topo.edges())
          thin.line(x[static_cast<std::size_t>(e[0])], x[static_cast<std::size_t>(e[1])], pal.edge);
      }
    }
    const ContactSet& c = contacts();
    if (draw_options.colliding_edges) {
      const std::vector<bool> hit = render::colliding_edges(topo, c);
      for (Index e = 0; e < topo.num_edges(); ++e) {
        if (!hit[static_cast<std::size_t>(e)]) continue;
        thick.line(x[static_cast<std::size_t>(topo.edge(e)[0])],
                   x[static_cast<std::size_t>(topo.edge(e)[1])], pal.colliding);
      }
    }
    if (draw_options.contact_segments) {
      for (const render::Segment& s : render::contact_segments(topo, x, c))
        thin.line(s.a, s.b, pal.contact);
    }
    if (show_active_pairs) active_pairs(thin);
    if (kdop_level >= 0) kdop_boxes(thin);
    if (grabbed_ >= 0 && sim_ && sim_->field().drag) {
      thin.line(x[static_cast<std::size_t>(grabbed_)], sim_->field().drag->target,
                render::Rgb{255, 140, 0});
      thin.point(sim_->field().drag->target, render::Rgb{255, 140, 0});
    }
    gl.batch(thin, 1.0f, 5.0f);
    gl.batch(thick, 2.5f, 5.0f);
  }

  /// The boxes of one level of the kdop detector's hierarchy (x, y, z slabs of its k-DOPs) as
  /// refitted by its last update.
  void kdop_boxes(Batch& batch) {
    const Detector* d = sim_ ? &sim_->detector() : playback_detector_.get();
    const BoundingHierarchy* kdop = d != nullptr ? d->hierarchy() : nullptr;
    if (kdop == nullptr) return;
    const render::Rgb colour{60, 170, 90};
    for (const Bounds& b : kdop->node_boxes(kdop_level)) {
      const auto corner = [&](int i) {
        return Vec3(i & 1 ? b.max.x() : b.min.x(), i & 2 ? b.max.y() : b.min.y(), i & 4 ? b.max.z() : b.min.z());
      };
      for (int i = 0; i < 8; ++i) {
        for (int bit : {1, 2, 4}) {
          if (!(i & bit)) batch.line(corner(i), corner(i | bit), colour);
        }
      }
    }
  }

  /// The stochastic detector's near (active) pairs: those the simulation's own detector (or the
  /// playback detector) keeps after its last update.
  void active_pairs(Batch& batch) {
    const Detector* d = sim_ ? &sim_->detector() : playback_detector_.get();
    const auto* stochastic = dynamic_cast<const StochasticDetector*>(d);
    if (stochastic == nullptr) return;
    const StochasticDetector& det = *stochastic;
    const Topology& topo = topology();
    const PositionsView x = positions();
    const auto vertex = [&](Index v) { return x[static_cast<std::size_t>(v)]; };
    const auto edge = [&](Index e) {
      return 0.5 * (vertex(topo.edge(e)[0]) + vertex(topo.edge(e)[1]));
    };
    const auto face = [&](Index f) {
      const Face& t = topo.face(f);
      return (vertex(t[0]) + vertex(t[1]) + vertex(t[2])) / 3.0;
    };
    const render::Rgb colour{230, 140, 0};
    for (const PairType type : {PairType::VV, PairType::EE, PairType::VF, PairType::EF}) {
      if (!det.runs(type)) continue;
      for (const PrimitivePair& p : det.near_pairs(type)) {
        switch (type) {
          case PairType::VV: batch.line(vertex(p.a), vertex(p.b), colour); break;
          case PairType::EE: batch.line(edge(p.a), edge(p.b), colour); break;
          case PairType::VF: batch.line(vertex(p.a), face(p.b), colour); break;
          case PairType::EF: batch.line(edge(p.a), face(p.b), colour); break;
        }
      }
    }
  }

  // --- mouse --------------------------------------------------------------------------------
  void mouse_down(double x, double y, int width, int height) {
    if (!sim_) return;
    grabbed_ = render::pick_vertex(camera, positions(), x, y, width, height);
    if (grabbed_ < 0) return;
    const auto s = camera.project(positions()[static_cast<std::size_t>(grabbed_)], width, height);
    grab_depth_ = s ? s->depth : camera.distance;
    mouse_drag(x, y, width, height);
  }
  void mouse_drag(double x, double y, int width, int height) {
    if (!sim_ || grabbed_ < 0) return;
    sim::DragForce drag;
    drag.vertex = grabbed_;
    drag.target = camera.unproject(x, y, grab_depth_, width, height);
    drag.stiffness = drag_stiffness;
    drag.damping = drag_damping;
    sim_->field().drag = drag;
  }
  void mouse_up() {
    grabbed_ = -1;
    if (sim_) sim_->field().drag.reset();
  }
  bool grabbing() const { return grabbed_ >= 0; }

  void fit(double aspect) { camera.fit(compute_bounds(positions()), aspect); }

  // --- panel --------------------------------------------------------------------------------
  void panel(double fps, bool& screenshot_request) {
    ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(360, 0), ImGuiCond_FirstUseEver);
    ImGui::Begin("crumple-view");
    ImGui::TextWrapped("%s", source_.c_str());
    if (ImGui::Button(paused ? "Play (space)" : "Pause (space)")) paused = !paused;
    ImGui::SameLine();
    if (ImGui::Button("Step (S)")) step_request = true;
    ImGui::SameLine();
    if (ImGui::Button("Reset (R)")) reset();
    ImGui::SliderFloat("speed", &speed, 0.1f, 10.0f, "%.1f frames/redraw",
                       ImGuiSliderFlags_Logarithmic);

    if (ImGui::CollapsingHeader("Detection and simulation", ImGuiTreeNodeFlags_DefaultOpen))
      settings_panel();
    if (ImGui::CollapsingHeader("Drawing", ImGuiTreeNodeFlags_DefaultOpen)) {
      ImGui::Checkbox("surface", &draw_options.surface);
      ImGui::SameLine();
      ImGui::Checkbox("wireframe (W)", &draw_options.wireframe);
      ImGui::Checkbox("masses and springs only", &draw_options.masses_springs);
      ImGui::Checkbox("colliding edges (red)", &draw_options.colliding_edges);
      ImGui::SameLine();
      ImGui::Checkbox("VF segments", &draw_options.contact_segments);
      if (settings_.method.method() == Method::Stochastic) {
        ImGui::Checkbox("stochastic active (near) pairs", &show_active_pairs);
      } else {
        ImGui::TextDisabled("active pairs: stochastic detector only");
      }
      const Detector* shown = sim_ ? &sim_->detector() : playback_detector_.get();
      if (const BoundingHierarchy* kdop = shown != nullptr ? shown->hierarchy() : nullptr) {
        bool on = kdop_level >= 0;
        if (ImGui::Checkbox("k-DOP boxes", &on)) kdop_level = on ? 0 : -1;
        if (on && kdop->levels() > 0) {
          ImGui::SameLine();
          ImGui::SliderInt("level", &kdop_level, 0, kdop->levels() - 1);
        }
      } else {
        ImGui::TextDisabled("k-DOP boxes: kdop detector only");
      }
    }
    if (ImGui::CollapsingHeader("Statistics", ImGuiTreeNodeFlags_DefaultOpen)) {
      ImGui::Text("%.1f fps   frame %lld", fps, static_cast<long long>(stats_.frame));
      ImGui::Text("ms: integrate %.2f  detect %.2f  response %.2f", stats_.integrate_ms,
                  stats_.detect_ms, stats_.response_ms);
      ImGui::Text("contacts: vf %zu  ee %zu  tt %zu", stats_.vf, stats_.ee, stats_.tt);
      ImGui::Text("edges in collision: %.1f%%", 100 * stats_.collision_share);
      if (ImGui::Button("Recall vs naive (this frame)")) compute_recall();
      if (!recall_.empty()) {
        ImGui::SameLine();
        ImGui::TextUnformatted(recall_.c_str());
      }
    }
    if (ImGui::CollapsingHeader("Files")) {
      ImGui::InputText("X3D", x3d_path_.data(), x3d_path_.size());
      ImGui::SameLine();
      if (ImGui::Button("Save")) save_x3d(x3d_path_.data());
      ImGui::InputText("PNG", png_path_.data(), png_path_.size());
      ImGui::SameLine();
      if (ImGui::Button("Shot (P)")) screenshot_request = true;
    }
    ImGui::TextDisabled(
        "left drag: orbit  right drag: pan  wheel: zoom\nctrl+left or middle: grab a vertex  F: "
        "fit");
    if (!message_.empty()) ImGui::TextColored(ImVec4(1, 0.4f, 0.3f, 1), "%s", message_.c_str());
    ImGui::End();
  }

  void settings_panel() {
    sim::Settings next = settings_;
    bool changed = false;
    const auto methods = all_methods();
    std::vector<const char*> names;
    for (const MethodInfo& m : methods) names.push_back(m.name.data());
    changed |=
        ImGui::Combo("detector", &method_index_, names.data(), static_cast<int>(names.size()));
    if (methods[static_cast<std::size_t>(method_index_)].method == Method::Stochastic) {
      changed |= ImGui::Combo("variant", &variant_index_, kVariants.data(),
                              static_cast<int>(kVariants.size()));
      changed |= ImGui::Combo("setting", &setting_index_,
                              "default\0thesis 1 (10 active, propagation)\0thesis 2 (100, none)\0");
    }
    ImGui::InputText("params", params_.data(), params_.size());
    ImGui::SameLine();
    changed |= ImGui::Button("Apply");
    double thickness = settings_.detector.thickness;
    if (ImGui::InputDouble("thickness (m)", &thickness, 0, 0, "%.5g",
                           ImGuiInputTextFlags_EnterReturnsTrue) &&
        thickness >= 0) {
      next.detector.thickness = thickness;
      changed = true;
    }
    if (sim_) {
      int integrator = static_cast<int>(settings_.integrator);
      std::vector<const char*> integrators;
      std::vector<std::string> storage;
      for (const sim::IntegratorKind k : sim::all_integrators())
        storage.emplace_back(sim::to_string(k));
      for (const std::string& s : storage) integrators.push_back(s.c_str());
      if (ImGui::Combo("integrator", &integrator, integrators.data(),
                       static_cast<int>(integrators.size()))) {
        next.integrator = sim::all_integrators()[static_cast<std::size_t>(integrator)];
        changed = true;
      }
      changed |= ImGui::Checkbox("collision response", &next.response);
      ImGui::SliderFloat("drag stiffness", &drag_stiffness, 1, 1000, "%.0f N/m",
                         ImGuiSliderFlags_Logarithmic);
    }
    ImGui::TextDisabled("%s", settings_.method.to_string().c_str());
    if (!changed) return;
    try {
      next.method = MethodSpec::parse(method_spec_text());
      apply_settings(next);
      message_.clear();
    } catch (const Error& e) {
      message_ = e.what();
    }
  }

  std::string method_spec_text() const {
    const MethodInfo& m = all_methods()[static_cast<std::size_t>(method_index_)];
    std::string text(m.name);
    std::string params;
    if (m.method == Method::Stochastic) {
      params.append("variant=").append(kVariants[static_cast<std::size_t>(variant_index_)]);
      if (setting_index_ > 0) params.append(",setting=").append(std::to_string(setting_index_));
    }
    const std::string extra(params_.data());
    if (!extra.empty()) params.append(params.empty() ? "" : ",").append(extra);
    if (!params.empty()) text.append(":").append(params);
    return text;
  }

  void sync_method_ui() {
    const auto methods = all_methods();
    for (std::size_t i = 0; i < methods.size(); ++i) {
      if (methods[i].method == settings_.method.method()) method_index_ = static_cast<int>(i);
    }
    std::string extra;
    for (const auto& [key, value] : settings_.method.params()) {
      if (key == "variant") {
        for (std::size_t v = 0; v < kVariants.size(); ++v) {
          if (value == kVariants[v]) variant_index_ = static_cast<int>(v);
        }
      } else if (key == "setting") {
        setting_index_ = std::clamp(std::atoi(value.c_str()), 0, 2);
      } else {
        extra.append(extra.empty() ? "" : ",").append(key).append("=").append(value);
      }
    }
    params_.fill('\0');
    std::strncpy(params_.data(), extra.c_str(), params_.size() - 1);
  }

  void compute_recall() {
    DetectorOptions options = settings_.detector;
    auto naive = make_detector(MethodSpec(Method::Naive), options);
    naive->set_topology(frames_ ? frames_->first().topology_ptr() : sim_->model().topology_ptr());
    ContactSet reference;
    naive->update(positions(), reference);
    const ContactMatch m = match_contacts(contacts(), reference);
    char buf[160];
    std::snprintf(buf, sizeof buf, "recall %.3f (%zu of %zu, %zu false)", m.recall(), m.found,
                  m.reference, m.false_contacts);
    recall_ = buf;
  }

  void save_x3d(const std::string& path) {
    try {
      if (sim_) {
        io::write_mass_spring(path, cli::to_mass_spring(sim_->model(), sim_->state()));
      } else {
        io::write_x3d(path, positions(), topology().faces());
      }
      message_ = "saved " + path;
    } catch (const Error& e) {
      message_ = e.what();
    }
  }

  std::string png_path() const { return png_path_.data(); }
  const std::string& recall_text() const { return recall_; }
  void set_message(std::string m) { message_ = std::move(m); }

  render::Camera camera;
  render::DrawOptions draw_options;
  render::Lighting lighting;
  bool paused = false;
  bool step_request = false;
  bool show_active_pairs = false;
  int kdop_level = -1;  ///< level of the k-DOP hierarchy drawn, -1 = none
  float speed = 1;
  float drag_stiffness = 20;
  float drag_damping = 0.5f;

 private:
  Options options_;
  std::string source_;
  sim::Scene scene_;
  sim::Settings settings_;
  std::optional<sim::Simulation> sim_;
  sim::FrameStats stats_;
  // Frame playback.
  std::optional<io::FrameSequence> frames_;
  std::size_t frame_index_ = 0;
  std::unique_ptr<Detector> playback_detector_;
  std::string playback_spec_;
  Positions playback_x_;
  ContactSet playback_contacts_;
  // Overlay of the stochastic detector's active pairs.
  // Mouse grab.
  Index grabbed_ = -1;
  double grab_depth_ = 1;
  // Panel state.
  int method_index_ = 0, variant_index_ = 2, setting_index_ = 0;
  std::array<char, 256> params_{};
  std::array<char, 512> x3d_path_{"crumple-view-state.x3d"};
  std::array<char, 512> png_path_{"crumple-view.png"};
  std::string recall_, message_;
};

/// Reads the back buffer (what was just drawn, without the panel) into a picture.
render::Picture read_framebuffer(int width, int height) {
  render::Picture picture(width, height);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadBuffer(GL_BACK);
  glReadPixels(0, 0, width, height, GL_RGB, GL_UNSIGNED_BYTE, picture.data().data());
  picture.flip_vertically();
  return picture;
}

struct Input {
  App* app = nullptr;
  double scroll = 0;
  bool key_space = false, key_step = false, key_reset = false, key_fit = false, key_wire = false,
       key_shot = false;
};

void on_scroll(GLFWwindow* window, double, double dy) {
  static_cast<Input*>(glfwGetWindowUserPointer(window))->scroll += dy;
}

void on_key(GLFWwindow* window, int key, int, int action, int) {
  if (action != GLFW_PRESS && action != GLFW_REPEAT) return;
  auto* in = static_cast<Input*>(glfwGetWindowUserPointer(window));
  switch (key) {
    case GLFW_KEY_SPACE: in->key_space = true; break;
    case GLFW_KEY_S:
    case GLFW_KEY_RIGHT: in->key_step = true; break;
    case GLFW_KEY_R: in->key_reset = true; break;
    case GLFW_KEY_F: in->key_fit = true; break;
    case GLFW_KEY_W: in->key_wire = true; break;
    case GLFW_KEY_P: in->key_shot = true; break;
    case GLFW_KEY_ESCAPE: glfwSetWindowShouldClose(window, GLFW_TRUE); break;
    default: break;
  }
}

void on_glfw_error(int code, const char* text) {
  std::fprintf(stderr, "crumple-view: GLFW error %d: %s\n", code, text);
}

int run(Options options) {
  int width = 1024, height = 720;
  {
    char extra = 0;
    if (std::sscanf(options.size.c_str(), "%dx%d%c", &width, &height, &extra) != 2 || width < 64 ||
        height < 64 || width > 8192 || height > 8192) {
      throw InputError("--size expects WxH with 64..8192 pixels a side, got '" + options.size +
                       "'");
    }
  }
  if (options.frames < 0) throw InputError("--frames must be >= 0");
  const bool automated = options.exit;
  const std::string screenshot = options.screenshot;
  const long long frames = options.frames;
  const bool print_recall = options.recall;
  const bool wireframe = options.wireframe, springs = options.springs,
             active_pairs = options.active_pairs;
  const int kdop_level = options.kdop_level;
  App app(std::move(options));  // loads before any window opens: bad input fails fast

  glfwSetErrorCallback(on_glfw_error);
  if (!glfwInit()) throw Error("cannot initialise GLFW (no display? try xvfb-run)");
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_SAMPLES, automated ? 0 : 4);
  GLFWwindow* window = glfwCreateWindow(width, height, "crumple-view", nullptr, nullptr);
  if (window == nullptr) {
    glfwTerminate();
    throw Error("cannot open an OpenGL 3.3 core window");
  }
  glfwMakeContextCurrent(window);
  glfwSwapInterval(automated ? 0 : 1);
  Input input;
  input.app = &app;
  glfwSetWindowUserPointer(window, &input);
  glfwSetScrollCallback(window, on_scroll);  // installed first: ImGui chains to them
  glfwSetKeyCallback(window, on_key);

  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGui::GetIO().IniFilename = nullptr;
  ImGui::StyleColorsDark();
  ImGui_ImplGlfw_InitForOpenGL(window, true);
  ImGui_ImplOpenGL3_Init("#version 330");
  int status = 0;
  {
    GlDraw gl;
    for (long long k = 0; k < frames; ++k) app.advance();
    {
      int fw = 0, fh = 0;
      glfwGetFramebufferSize(window, &fw, &fh);
      app.fit(static_cast<double>(fw) / std::max(fh, 1));
    }
    if (automated) app.paused = true;
    app.draw_options.wireframe = wireframe;
    app.draw_options.masses_springs = springs;
    app.show_active_pairs = active_pairs;
    app.kdop_level = kdop_level;
    if (print_recall) {
      app.compute_recall();
      std::printf("crumple-view: %s\n", app.recall_text().c_str());
    }
    bool screenshot_request = !screenshot.empty();
    double last_x = 0, last_y = 0;
    bool dragging_view = false;
    float accumulated = 0;
    while (!glfwWindowShouldClose(window)) {
      glfwPollEvents();
      int fw = 0, fh = 0, ww = 0, wh = 0;
      glfwGetFramebufferSize(window, &fw, &fh);
      glfwGetWindowSize(window, &ww, &wh);
      if (fw <= 0 || fh <= 0) continue;
      ImGui_ImplOpenGL3_NewFrame();
      ImGui_ImplGlfw_NewFrame();
      ImGui::NewFrame();
      const ImGuiIO& io = ImGui::GetIO();

      // Keyboard.
      if (!io.WantCaptureKeyboard) {
        if (input.key_space) app.paused = !app.paused;
        if (input.key_step) app.step_request = true;
        if (input.key_reset) app.reset();
        if (input.key_fit) app.fit(static_cast<double>(fw) / fh);
        if (input.key_wire) app.draw_options.wireframe = !app.draw_options.wireframe;
        if (input.key_shot) screenshot_request = true;
      }
      input.key_space = input.key_step = input.key_reset = input.key_fit = input.key_wire =
          input.key_shot = false;

      // Mouse, in framebuffer pixels.
      double mx = 0, my = 0;
      glfwGetCursorPos(window, &mx, &my);
      mx *= static_cast<double>(fw) / std::max(ww, 1);
      my *= static_cast<double>(fh) / std::max(wh, 1);
      const bool left = glfwGetMouseButton(window, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS;
      const bool right = glfwGetMouseButton(window, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS;
      const bool middle = glfwGetMouseButton(window, GLFW_MOUSE_BUTTON_MIDDLE) == GLFW_PRESS;
      const bool ctrl = glfwGetKey(window, GLFW_KEY_LEFT_CONTROL) == GLFW_PRESS ||
                        glfwGetKey(window, GLFW_KEY_RIGHT_CONTROL) == GLFW_PRESS;
      const bool grab_button = middle || (left && ctrl);
      if (app.grabbing()) {
        if (grab_button) {
          app.mouse_drag(mx, my, fw, fh);
        } else {
          app.mouse_up();
        }
      } else if (!io.WantCaptureMouse) {
        if (grab_button && !dragging_view) {
          app.mouse_down(mx, my, fw, fh);
        } else if (left || right) {
          if (dragging_view) {
            if (left) app.camera.orbit(-0.3 * (mx - last_x), 0.3 * (my - last_y));
            if (right) app.camera.pan(-(mx - last_x) / fh, (my - last_y) / fh);
          }
          dragging_view = true;
        }
        if (input.scroll != 0) app.camera.zoom(std::pow(0.9, input.scroll));
      }
      if (!left && !right) dragging_view = false;
      input.scroll = 0;
      last_x = mx;
      last_y = my;

      // Simulation.
      try {
        if (!app.paused) {
          accumulated += app.speed;
          while (accumulated >= 1) {
            app.advance();
            accumulated -= 1;
          }
        } else if (app.step_request) {
          app.advance();
        }
        app.step_request = false;
      } catch (const Error& e) {
        app.paused = true;
        app.set_message(e.what());
      }

      app.draw(gl, fw, fh);
      if (screenshot_request) {
        const std::string path = !screenshot.empty() ? screenshot : app.png_path();
        try {
          render::write_png(path, read_framebuffer(fw, fh));
          app.set_message("saved " + path);
          if (automated) std::printf("crumple-view: wrote %s (%dx%d)\n", path.c_str(), fw, fh);
        } catch (const Error& e) {
          app.set_message(e.what());
          if (automated) {
            std::fprintf(stderr, "crumple-view: error: %s\n", e.what());
            status = 1;
          }
        }
        screenshot_request = false;
      }
      app.panel(io.Framerate, screenshot_request);  // drawn after the screenshot: not in it
      ImGui::Render();
      ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
      glfwSwapBuffers(window);
      if (automated) break;
    }
  }
  ImGui_ImplOpenGL3_Shutdown();
  ImGui_ImplGlfw_Shutdown();
  ImGui::DestroyContext();
  glfwDestroyWindow(window);
  glfwTerminate();
  return status;
}

}  // namespace

}  // namespace crumple::viewer

int main(int argc, char** argv) {
  CLI::App cli{
      "crumple-view — interactive viewer: runs a cloth scene live with self-collision detection.\n"
      "Left drag: orbit; right drag: pan; wheel: zoom; Ctrl+left or middle drag: grab a vertex;\n"
      "space: pause; S: step; R: reset; F: fit; W: wireframe; P: screenshot."};
  crumple::viewer::Options options;
  cli.add_option(
         "INPUT", options.input,
         "Scene SPEC (e.g. hanging-cloth:nx=20), a mesh / MassSpring file (.x3d .obj .ply .off)\n"
         "or a folder of frame files to play back")
      ->capture_default_str();
  cli.add_option("-p,--param", options.params, "Scene key=value (repeatable)");
  cli.add_option("-n,--frames", options.frames, "Frames to simulate before the first picture")
      ->capture_default_str();
  cli.add_option("-m,--method", options.method, "Detection method SPEC; default: the scene's");
  cli.add_option("-t,--thickness", options.thickness,
                 "Contact thickness (scene units); default: the scene's");
  cli.add_option("-s,--seed", options.seed, "Seed of the scene's random perturbation")
      ->capture_default_str();
  cli.add_option("--size", options.size, "Window size WxH")->capture_default_str();
  cli.add_option("--screenshot", options.screenshot,
                 "Save the first picture (GL framebuffer) to this PNG");
  cli.add_flag("--wireframe", options.wireframe, "Start with the wireframe on");
  cli.add_flag("--springs", options.springs, "Start drawing the masses and springs only");
  cli.add_flag("--active-pairs", options.active_pairs,
               "Start showing the stochastic detector's active pairs");
  cli.add_option("--kdop-level", options.kdop_level,
                 "Draw the boxes of this level of the kdop detector's hierarchy (0 = root)")
      ->check(CLI::Range(0, 64));
  cli.add_flag("--recall", options.recall,
               "Print the recall of the detector against naive for the first picture");
  cli.add_flag("--exit", options.exit, "Draw one frame (after --frames), save --screenshot, exit");
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return cli.exit(e);
  }
  try {
    return crumple::viewer::run(options);
  } catch (const crumple::Error& e) {
    std::cerr << "crumple-view: error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "crumple-view: internal error: " << e.what() << "\n";
    return 2;
  }
}
