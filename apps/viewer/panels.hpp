#pragma once
// crumple-view's Dear ImGui panel: playback buttons, the detector and simulation settings, the
// drawing switches, statistics and files. It edits the App; its own state is only the widgets'.

#include "app.hpp"

#include <array>
#include <string>

namespace crumple::viewer {

class Panels {
 public:
  /// The widgets start from `settings.method` (name, stochastic variant and setting, other keys).
  explicit Panels(const MethodSpec& method);

  /// Draws the panel for this frame; sets `screenshot_request` when its button is pressed.
  void draw(App& app, double fps, bool& screenshot_request);

  std::string png_path() const { return png_path_.data(); }

 private:
  void settings_panel(App& app);
  void drawing_panel(App& app);
  void statistics_panel(App& app, double fps);
  /// The method spec the widgets describe.
  std::string method_spec_text() const;

  int method_index_ = 0, variant_index_ = 2, setting_index_ = 0;
  std::array<char, 256> params_{};
  std::array<char, 512> x3d_path_{"crumple-view-state.x3d"};
  std::array<char, 512> png_path_{"crumple-view.png"};
};

}  // namespace crumple::viewer
