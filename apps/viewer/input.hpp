#pragma once
// Keyboard and mouse for crumple-view: GLFW callbacks collect key presses and wheel turns;
// `handle_input` turns them, and the mouse buttons, into actions on the App once per redraw.

#include "app.hpp"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

namespace crumple::viewer {

/// What the callbacks collected since the last redraw, and the mouse's last position.
struct Input {
  double scroll = 0;
  bool key_space = false, key_step = false, key_reset = false, key_fit = false, key_wire = false,
       key_shot = false;
  double last_x = 0, last_y = 0;
  bool dragging_view = false;
};

/// Installs the scroll and key callbacks writing to `input` (before ImGui's, which chain to them).
void install_callbacks(GLFWwindow* window, Input& input);

/// Applies this redraw's keys and mouse to `app`: orbit, pan, zoom, grab a vertex, pause, step,
/// reset, fit, wireframe; `screenshot_request` is set by P. `want_keyboard` / `want_mouse`: the
/// panel has them. `fw` × `fh` framebuffer pixels, `ww` × `wh` window coordinates.
void handle_input(GLFWwindow* window, App& app, Input& input, bool want_keyboard, bool want_mouse, int fw, int fh,
                  int ww, int wh, bool& screenshot_request);

}  // namespace crumple::viewer
