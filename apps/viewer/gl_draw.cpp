#include "gl_draw.hpp"

#define GL_GLEXT_PROTOTYPES
#include <GL/gl.h>
#include <GL/glext.h>

#include <algorithm>
#include <stdexcept>
#include <string>

namespace crumple::viewer {

namespace {

const char* kMeshVertex = R"(#version 330 core
layout(location = 0) in vec3 position;
uniform mat4 mvp;
uniform mat4 mv;
out vec3 view_position;
void main() {
  view_position = (mv * vec4(position, 1.0)).xyz;
  gl_Position = mvp * vec4(position, 1.0);
}
)";

// Flat normal from screen-space derivatives, turned towards the eye (two-sided), headlight.
const char* kMeshFragment = R"(#version 330 core
in vec3 view_position;
uniform vec3 front_colour;
uniform vec3 back_colour;
uniform vec3 light;
uniform float ambient;
uniform float diffuse;
out vec4 colour;
void main() {
  vec3 n = normalize(cross(dFdx(view_position), dFdy(view_position)));
  if (dot(n, -view_position) < 0.0) n = -n;
  vec3 base = gl_FrontFacing ? front_colour : back_colour;
  colour = vec4(base * (ambient + diffuse * max(0.0, dot(n, light))), 1.0);
}
)";

const char* kLineVertex = R"(#version 330 core
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 colour_in;
uniform mat4 mvp;
uniform float point_size;
out vec3 colour_v;
void main() {
  colour_v = colour_in;
  gl_PointSize = point_size;
  gl_Position = mvp * vec4(position, 1.0);
}
)";

const char* kLineFragment = R"(#version 330 core
in vec3 colour_v;
out vec4 colour;
void main() { colour = vec4(colour_v, 1.0); }
)";

GLuint compile(GLenum type, const char* source) {
  const GLuint shader = glCreateShader(type);
  glShaderSource(shader, 1, &source, nullptr);
  glCompileShader(shader);
  GLint ok = 0;
  glGetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[2048] = {};
    glGetShaderInfoLog(shader, sizeof log, nullptr, log);
    throw std::runtime_error(std::string("shader compilation failed: ").append(log));
  }
  return shader;
}

GLuint link(const char* vertex, const char* fragment) {
  const GLuint v = compile(GL_VERTEX_SHADER, vertex), f = compile(GL_FRAGMENT_SHADER, fragment);
  const GLuint program = glCreateProgram();
  glAttachShader(program, v);
  glAttachShader(program, f);
  glLinkProgram(program);
  glDeleteShader(v);
  glDeleteShader(f);
  GLint ok = 0;
  glGetProgramiv(program, GL_LINK_STATUS, &ok);
  if (!ok) {
    char log[2048] = {};
    glGetProgramInfoLog(program, sizeof log, nullptr, log);
    throw std::runtime_error(std::string("shader link failed: ").append(log));
  }
  return program;
}

void to_float(const Eigen::Matrix4d& m, float* out) {
  for (int c = 0; c < 4; ++c) {
    for (int r = 0; r < 4; ++r) out[4 * c + r] = static_cast<float>(m(r, c));  // column-major
  }
}

void set_colour(GLuint program, const char* name, render::Rgb c) {
  glUniform3f(glGetUniformLocation(program, name), c.r / 255.0f, c.g / 255.0f, c.b / 255.0f);
}

}  // namespace

void Batch::line(const Vec3& a, const Vec3& b, render::Rgb c) {
  const float r = c.r / 255.0f, g = c.g / 255.0f, bl = c.b / 255.0f;
  lines.push_back(
      {static_cast<float>(a.x()), static_cast<float>(a.y()), static_cast<float>(a.z()), r, g, bl});
  lines.push_back(
      {static_cast<float>(b.x()), static_cast<float>(b.y()), static_cast<float>(b.z()), r, g, bl});
}

void Batch::point(const Vec3& p, render::Rgb c) {
  points.push_back({static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()),
                    c.r / 255.0f, c.g / 255.0f, c.b / 255.0f});
}

GlDraw::GlDraw() {
  mesh_program_ = link(kMeshVertex, kMeshFragment);
  line_program_ = link(kLineVertex, kLineFragment);
  glGenVertexArrays(1, &vao_);
  glGenBuffers(1, &mesh_vbo_);
  glGenBuffers(1, &mesh_ebo_);
  glGenBuffers(1, &line_vbo_);
}

GlDraw::~GlDraw() {
  glDeleteBuffers(1, &mesh_vbo_);
  glDeleteBuffers(1, &mesh_ebo_);
  glDeleteBuffers(1, &line_vbo_);
  glDeleteVertexArrays(1, &vao_);
  glDeleteProgram(mesh_program_);
  glDeleteProgram(line_program_);
}

void GlDraw::begin(const render::Camera& camera, int width, int height,
                   const render::Palette& palette) {
  glViewport(0, 0, width, height);
  glClearColor(palette.background.r / 255.0f, palette.background.g / 255.0f,
               palette.background.b / 255.0f, 1);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);
  glEnable(GL_PROGRAM_POINT_SIZE);
  const double aspect = static_cast<double>(width) / std::max(height, 1);
  to_float(camera.projection_matrix(aspect) * camera.view_matrix(), mvp_);
  to_float(camera.view_matrix(), mv_);
}

void GlDraw::surface(std::span<const Face> faces, PositionsView positions,
                     const render::Palette& palette, const render::Lighting& lighting) {
  std::vector<float> xyz;
  xyz.reserve(3 * positions.size());
  for (const Vec3& p : positions) {
    xyz.push_back(static_cast<float>(p.x()));
    xyz.push_back(static_cast<float>(p.y()));
    xyz.push_back(static_cast<float>(p.z()));
  }
  glBindVertexArray(vao_);
  glBindBuffer(GL_ARRAY_BUFFER, mesh_vbo_);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(xyz.size() * sizeof(float)), xyz.data(),
               GL_STREAM_DRAW);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, mesh_ebo_);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(faces.size() * sizeof(Face)),
               faces.data(), GL_STREAM_DRAW);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), nullptr);
  glDisableVertexAttribArray(1);
  glUseProgram(mesh_program_);
  glUniformMatrix4fv(glGetUniformLocation(mesh_program_, "mvp"), 1, GL_FALSE, mvp_);
  glUniformMatrix4fv(glGetUniformLocation(mesh_program_, "mv"), 1, GL_FALSE, mv_);
  set_colour(mesh_program_, "front_colour", palette.front);
  set_colour(mesh_program_, "back_colour", palette.back);
  const Vec3 l = lighting.direction.normalized();
  glUniform3f(glGetUniformLocation(mesh_program_, "light"), static_cast<float>(l.x()),
              static_cast<float>(l.y()), static_cast<float>(l.z()));
  glUniform1f(glGetUniformLocation(mesh_program_, "ambient"), static_cast<float>(lighting.ambient));
  glUniform1f(glGetUniformLocation(mesh_program_, "diffuse"), static_cast<float>(lighting.diffuse));
  // Push the surface back a little so edges lying on it stay visible.
  glEnable(GL_POLYGON_OFFSET_FILL);
  glPolygonOffset(1.0f, 2.0f);
  glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(3 * faces.size()), GL_UNSIGNED_INT, nullptr);
  glDisable(GL_POLYGON_OFFSET_FILL);
}

void GlDraw::batch(const Batch& batch, float line_width, float point_size) {
  glBindVertexArray(vao_);
  glUseProgram(line_program_);
  glUniformMatrix4fv(glGetUniformLocation(line_program_, "mvp"), 1, GL_FALSE, mvp_);
  glUniform1f(glGetUniformLocation(line_program_, "point_size"), point_size);
  glBindBuffer(GL_ARRAY_BUFFER, line_vbo_);
  const auto draw = [&](const std::vector<ColouredVertex>& v, GLenum mode) {
    if (v.empty()) return;
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(v.size() * sizeof(ColouredVertex)),
                 v.data(), GL_STREAM_DRAW);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(ColouredVertex), nullptr);
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, sizeof(ColouredVertex),
                          reinterpret_cast<const void*>(3 * sizeof(float)));
    glDrawArrays(mode, 0, static_cast<GLsizei>(v.size()));
  };
  glLineWidth(line_width);
  draw(batch.lines, GL_LINES);
  glLineWidth(1.0f);
  draw(batch.points, GL_POINTS);
  glDisableVertexAttribArray(1);
}

}  // namespace crumple::viewer
