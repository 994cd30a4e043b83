#include "input.hpp"

#include <algorithm>
#include <cmath>

namespace crumple::viewer {

namespace {

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

}  // namespace

void install_callbacks(GLFWwindow* window, Input& input) {
  glfwSetWindowUserPointer(window, &input);
  glfwSetScrollCallback(window, on_scroll);
  glfwSetKeyCallback(window, on_key);
}

void handle_input(GLFWwindow* window, App& app, Input& input, bool want_keyboard, bool want_mouse, int fw, int fh,
                  int ww, int wh, bool& screenshot_request) {
  if (!want_keyboard) {
    if (input.key_space) app.paused = !app.paused;
    if (input.key_step) app.step_request = true;
    if (input.key_reset) app.reset();
    if (input.key_fit) app.fit(static_cast<double>(fw) / fh);
    if (input.key_wire) app.draw_options.wireframe = !app.draw_options.wireframe;
    if (input.key_shot) screenshot_request = true;
  }
  input.key_space = input.key_step = input.key_reset = input.key_fit = input.key_wire = input.key_shot = false;

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
  LiveSimulation* live = app.live();
  if (live && live->grabbed() >= 0) {
    if (grab_button) {
      live->drag(app.camera, mx, my, fw, fh);
    } else {
      live->release();
    }
  } else if (!want_mouse) {
    if (grab_button && !input.dragging_view) {
      if (live) live->grab(app.camera, mx, my, fw, fh);
    } else if (left || right) {
      if (input.dragging_view) {
        if (left) app.camera.orbit(-0.3 * (mx - input.last_x), 0.3 * (my - input.last_y));
        if (right) app.camera.pan(-(mx - input.last_x) / fh, (my - input.last_y) / fh);
      }
      input.dragging_view = true;
    }
    if (input.scroll != 0) app.camera.zoom(std::pow(0.9, input.scroll));
  }
  if (!left && !right) input.dragging_view = false;
  input.scroll = 0;
  input.last_x = mx;
  input.last_y = my;
}

}  // namespace crumple::viewer
