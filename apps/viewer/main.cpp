// crumple-view: interactive viewer. Opens a built-in scene, a mesh / MassSpring file or a
// folder of frames; runs the simulation live (library: sim::Simulation, make_detector) and
// draws it with the colouring of crumple::render: shaded surface lit on both sides, edges in
// collision in red, vertex-face contacts as segments. No algorithm lives here: it parses,
// calls the library and draws. This file holds the command line and the redraw loop; loading
// and playback (loading.*), the live simulation (simulation.*), what is drawn (app.*), the
// panel (panels.*) and the input (input.*) have their own.
//
// Automation: `crumple-view [INPUT] --frames N --screenshot out.png --exit` steps N frames,
// draws one frame, saves the GL framebuffer (glReadPixels) and exits.
#include "app.hpp"
#include "input.hpp"
#include "options.hpp"
#include "panels.hpp"
#include "progress.hpp"

#include <crumple/core/error.hpp>
#include <crumple/render/picture.hpp>

#include <CLI/CLI.hpp>

#define GL_GLEXT_PROTOTYPES
#include <GL/gl.h>
#include <GL/glext.h>

#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <map>
#include <string>

namespace crumple::viewer {

namespace {

/// Reads the back buffer (what was just drawn, without the panel) into a picture.
render::Picture read_framebuffer(int width, int height) {
  render::Picture picture(width, height);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadBuffer(GL_BACK);
  glReadPixels(0, 0, width, height, GL_RGB, GL_UNSIGNED_BYTE, picture.data().data());
  picture.flip_vertically();
  return picture;
}

void on_glfw_error(int code, const char* text) {
  std::fprintf(stderr, "crumple-view: GLFW error %d: %s\n", code, text);
}

/// A diverged simulation (back at its last good state): paused, with the message in the UI
/// and on stderr, so that the settings can be changed and the run resumed.
void on_divergence(App& app, const sim::DivergenceError& e) {
  app.paused = true;
  app.set_message(e.what());
  std::fprintf(stderr, "crumple-view: %s\n", e.what());
}

/// Advances, or steps once when paused and asked to; an error pauses and shows its message.
void simulate(App& app, float& accumulated) {
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
  } catch (const sim::DivergenceError& e) {
    app.step_request = false;
    on_divergence(app, e);
  } catch (const Error& e) {
    app.paused = true;
    app.set_message(e.what());
  }
}

int run(const Options& options) {
  int width = 1024, height = 720;
  {
    char extra = 0;
    if (std::sscanf(options.size.c_str(), "%dx%d%c", &width, &height, &extra) != 2 || width < 64 ||
        height < 64 || width > 8192 || height > 8192) {
      throw InputError("--size expects WxH with 64..8192 pixels a side, got '" + options.size + "'");
    }
  }
  if (options.frames < 0) throw InputError("--frames must be >= 0");
  const bool automated = options.exit;
  App app(load_input(options));  // loads before any window opens: bad input fails fast
  if (options.response_from >= 0) app.set_response_from(options.response_from);
  Panels panels(app.settings().method);

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
  install_callbacks(window, input);  // installed first: ImGui chains to them

  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGui::GetIO().IniFilename = nullptr;
  ImGui::StyleColorsDark();
  ImGui_ImplGlfw_InitForOpenGL(window, true);
  ImGui_ImplOpenGL3_Init("#version 330");
  int status = 0;
  {
    GlDraw gl;
    Progress progress("frame", options.frames);
    bool diverged = false;
    try {
      for (long long k = 0; k < options.frames; ++k) {
        app.advance();
        progress.update(k + 1);
        if (automated && app.clean_frame() == app.stats().frame) {
          std::printf("crumple-view: 0 intersecting triangle pairs at frame %lld\n",
                      static_cast<long long>(app.clean_frame()));
        }
      }
    } catch (const sim::DivergenceError& e) {
      progress.finish();
      on_divergence(app, e);
      diverged = true;
    }
    if (!diverged) progress.finish();
    if (diverged && automated) status = 1;  // a scripted run that diverged is a failure
    {
      int fw = 0, fh = 0;
      glfwGetFramebufferSize(window, &fw, &fh);
      app.fit(static_cast<double>(fw) / std::max(fh, 1));
    }
    if (automated) {
      app.paused = true;
      std::printf("crumple-view: %s, method %s, %lld frames, %.1f frames per second\n", app.source().c_str(),
                  app.settings().method.to_string().c_str(), options.frames, app.simulation_fps());
      if (app.simulating()) std::printf("crumple-view: %s\n", app.untangle_text().c_str());
    }
    app.draw_options.wireframe = options.wireframe;
    app.draw_options.masses_springs = options.springs;
    app.show_active_pairs = options.active_pairs;
    app.kdop_level = options.kdop_level;
    if (options.recall) {
      app.compute_recall();
      std::printf("crumple-view: %s\n", app.recall_text().c_str());
    }
    bool screenshot_request = !options.screenshot.empty();
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
      handle_input(window, app, input, io.WantCaptureKeyboard, io.WantCaptureMouse, fw, fh, ww, wh,
                   screenshot_request);
      simulate(app, accumulated);

      app.draw(gl, fw, fh);
      if (screenshot_request) {
        const std::string path = !options.screenshot.empty() ? options.screenshot : panels.png_path();
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
      panels.draw(app, io.Framerate, screenshot_request);  // drawn after the screenshot: not in it
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
  cli.add_option("-m,--method", options.method,
                 std::string("Detection method SPEC; default: ") + crumple::viewer::kDefaultMethod);
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
  cli.add_option("--response", options.response, "on|off: self-collision response; default: the scene's")
      ->transform(CLI::CheckedTransformer(std::map<std::string, bool>{{"on", true}, {"off", false}}));
  cli.add_option("--untangle", options.untangle,
                 "on|off: with the response on, untangle a cloth that already intersects itself "
                 "(default on)")
      ->transform(CLI::CheckedTransformer(std::map<std::string, bool>{{"on", true}, {"off", false}}));
  cli.add_option("--response-from", options.response_from,
                 "Run the frames before F with the response off, then on (the hanging cloth falls "
                 "through itself, then untangles)")
      ->check(CLI::NonNegativeNumber);
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
