#include "panels.hpp"

#include <crumple/core/error.hpp>

#include <imgui.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <vector>

namespace crumple::viewer {

namespace {

constexpr std::array<const char*, 4> kVariants{"simple", "propagate-by-convergence", "direct", "vertex"};

}  // namespace

Panels::Panels(const MethodSpec& method) {
  const auto methods = all_methods();
  for (std::size_t i = 0; i < methods.size(); ++i) {
    if (methods[i].method == method.method()) method_index_ = static_cast<int>(i);
  }
  std::string extra;
  for (const auto& [key, value] : method.params()) {
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
  std::strncpy(params_.data(), extra.c_str(), params_.size() - 1);
}

void Panels::draw(App& app, double fps, bool& screenshot_request) {
  ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowSize(ImVec2(360, 0), ImGuiCond_FirstUseEver);
  ImGui::Begin("crumple-view");
  ImGui::TextWrapped("%s", app.source().c_str());
  if (ImGui::Button(app.paused ? "Play (space)" : "Pause (space)")) app.paused = !app.paused;
  ImGui::SameLine();
  if (ImGui::Button("Step (S)")) app.step_request = true;
  ImGui::SameLine();
  if (ImGui::Button("Reset (R)")) app.reset();
  ImGui::SliderFloat("speed", &app.speed, 0.1f, 10.0f, "%.1f frames/redraw", ImGuiSliderFlags_Logarithmic);

  if (ImGui::CollapsingHeader("Detection and simulation", ImGuiTreeNodeFlags_DefaultOpen)) settings_panel(app);
  if (ImGui::CollapsingHeader("Drawing", ImGuiTreeNodeFlags_DefaultOpen)) drawing_panel(app);
  if (ImGui::CollapsingHeader("Statistics", ImGuiTreeNodeFlags_DefaultOpen)) statistics_panel(app, fps);
  if (ImGui::CollapsingHeader("Files")) {
    ImGui::InputText("X3D", x3d_path_.data(), x3d_path_.size());
    ImGui::SameLine();
    if (ImGui::Button("Save")) app.save_x3d(x3d_path_.data());
    ImGui::InputText("PNG", png_path_.data(), png_path_.size());
    ImGui::SameLine();
    if (ImGui::Button("Shot (P)")) screenshot_request = true;
  }
  ImGui::TextDisabled("left drag: orbit  right drag: pan  wheel: zoom\nctrl+left or middle: grab a vertex  F: fit");
  if (!app.message().empty()) ImGui::TextColored(ImVec4(1, 0.4f, 0.3f, 1), "%s", app.message().c_str());
  ImGui::End();
}

void Panels::settings_panel(App& app) {
  sim::Settings next = app.settings();
  bool changed = false;
  const auto methods = all_methods();
  std::vector<const char*> names;
  for (const MethodInfo& m : methods) names.push_back(m.name.data());
  changed |= ImGui::Combo("detector", &method_index_, names.data(), static_cast<int>(names.size()));
  if (methods[static_cast<std::size_t>(method_index_)].method == Method::Stochastic) {
    changed |= ImGui::Combo("variant", &variant_index_, kVariants.data(), static_cast<int>(kVariants.size()));
    changed |= ImGui::Combo("setting", &setting_index_,
                            "default\0thesis 1 (10 active, propagation)\0thesis 2 (100, none)\0");
  }
  ImGui::InputText("params", params_.data(), params_.size());
  ImGui::SameLine();
  changed |= ImGui::Button("Apply");
  double thickness = next.detector.thickness;
  if (ImGui::InputDouble("thickness (m)", &thickness, 0, 0, "%.5g", ImGuiInputTextFlags_EnterReturnsTrue) &&
      thickness >= 0) {
    next.detector.thickness = thickness;
    changed = true;
  }
  if (LiveSimulation* live = app.live()) {
    int integrator = static_cast<int>(next.integrator);
    std::vector<std::string> storage;
    for (const sim::IntegratorKind k : sim::all_integrators()) storage.emplace_back(sim::to_string(k));
    std::vector<const char*> integrators;
    for (const std::string& s : storage) integrators.push_back(s.c_str());
    if (ImGui::Combo("integrator", &integrator, integrators.data(), static_cast<int>(integrators.size()))) {
      next.integrator = sim::all_integrators()[static_cast<std::size_t>(integrator)];
      changed = true;
    }
    changed |= ImGui::Checkbox("collision response", &next.response);
    ImGui::SameLine();
    changed |= ImGui::Checkbox("untangle", &next.untangle);
    if (app.response_delayed()) {
      ImGui::TextDisabled("response off until frame %lld", static_cast<long long>(app.response_from()));
    }
    ImGui::SliderFloat("drag stiffness", &live->drag_stiffness, 1, 1000, "%.0f N/m", ImGuiSliderFlags_Logarithmic);
  }
  ImGui::TextDisabled("%s", app.settings().method.to_string().c_str());
  if (!changed) return;
  try {
    next.method = MethodSpec::parse(method_spec_text());
    app.apply_settings(next);
    app.set_message({});
  } catch (const Error& e) {
    app.set_message(e.what());
  }
}

void Panels::drawing_panel(App& app) {
  render::DrawOptions& d = app.draw_options;
  ImGui::Checkbox("surface", &d.surface);
  ImGui::SameLine();
  ImGui::Checkbox("wireframe (W)", &d.wireframe);
  ImGui::Checkbox("masses and springs only", &d.masses_springs);
  ImGui::Checkbox("colliding edges (red)", &d.colliding_edges);
  ImGui::SameLine();
  ImGui::Checkbox("VF segments", &d.contact_segments);
  if (app.settings().method.method() == Method::Stochastic) {
    ImGui::Checkbox("stochastic active (near) pairs", &app.show_active_pairs);
  } else {
    ImGui::TextDisabled("active pairs: stochastic detector only");
  }
  if (const BoundingHierarchy* kdop = app.detector() != nullptr ? app.detector()->hierarchy() : nullptr) {
    bool on = app.kdop_level >= 0;
    if (ImGui::Checkbox("k-DOP boxes", &on)) app.kdop_level = on ? 0 : -1;
    if (on && kdop->levels() > 0) {
      ImGui::SameLine();
      ImGui::SliderInt("level", &app.kdop_level, 0, kdop->levels() - 1);
    }
  } else {
    ImGui::TextDisabled("k-DOP boxes: kdop detector only");
  }
}

void Panels::statistics_panel(App& app, double fps) {
  const sim::FrameStats& s = app.stats();
  ImGui::Text("%.1f fps (redraws)   frame %lld", fps, static_cast<long long>(s.frame));
  if (app.simulating()) ImGui::Text("simulation: %.1f frames per second", app.simulation_fps());
  ImGui::Text("ms: integrate %.2f  detect %.2f  response %.2f", s.integrate_ms, s.detect_ms, s.response_ms);
  ImGui::Text("contacts: vf %zu  ee %zu  tt %zu", s.vf, s.ee, s.tt);
  ImGui::Text("edges in collision: %.1f%%", 100 * s.collision_share);
  const std::string untangling = app.untangle_text();
  if (s.intersecting_pairs > 0) {
    ImGui::TextColored(ImVec4(1, 0.5f, 0.3f, 1), "%s", untangling.c_str());
  } else {
    ImGui::TextUnformatted(untangling.c_str());
  }
  if (ImGui::Button("Recall vs naive (this frame)")) app.compute_recall();
  if (!app.recall_text().empty()) {
    ImGui::SameLine();
    ImGui::TextUnformatted(app.recall_text().c_str());
  }
}

std::string Panels::method_spec_text() const {
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

}  // namespace crumple::viewer
