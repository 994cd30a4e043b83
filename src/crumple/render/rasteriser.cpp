#include <crumple/render/rasteriser.hpp>

#include <crumple/core/error.hpp>

#include <algorithm>
#include <cmath>

namespace crumple::render {

namespace {

Rgb shade(Rgb c, double intensity) {
  const auto f = [&](std::uint8_t v) {
    return static_cast<std::uint8_t>(std::clamp(std::lround(v * intensity), 0L, 255L));
  };
  return {f(c.r), f(c.g), f(c.b)};
}

}  // namespace

Rasteriser::Rasteriser(int width, int height, const Camera& camera, Rgb background, int supersample)
    : width_(width), height_(height), ss_(supersample), camera_(camera) {
  if (width < 1 || height < 1 || width > 16384 || height > 16384) {
    throw InputError(std::string("picture size must be 1..16384 on each side, got ")
                         .append(std::to_string(width))
                         .append("x")
                         .append(std::to_string(height)));
  }
  if (supersample < 1 || supersample > 4) {
    throw InputError(
        std::string("supersampling must be 1..4, got ").append(std::to_string(supersample)));
  }
  w_ = width * ss_;
  h_ = height * ss_;
  near_ = camera.distance / 1000;
  colour_.assign(static_cast<std::size_t>(w_) * h_, background);
  inv_depth_.assign(static_cast<std::size_t>(w_) * h_, 0.0);
}

bool Rasteriser::project(const Vec3& p, Projected& out) const {
  const auto s = camera_.project(p, w_, h_);
  if (!s || s->depth < near_) return false;
  out = {s->x, s->y, 1 / s->depth};
  return true;
}

void Rasteriser::triangle(const Vec3& a, const Vec3& b, const Vec3& c, Rgb front, Rgb back) {
  Projected p[3];
  if (!project(a, p[0]) || !project(b, p[1]) || !project(c, p[2])) return;
  // Lighting from the face normal turned towards the eye.
  Vec3 n = (b - a).cross(c - a);
  const double len = n.norm();
  const bool facing = n.dot(camera_.eye() - a) >= 0;
  double intensity = lighting.ambient + lighting.diffuse;
  if (len > 0) {
    n /= len;
    if (!facing) n = -n;
    const Vec3 l =
        (lighting.direction.x() * camera_.right() + lighting.direction.y() * camera_.up() -
         lighting.direction.z() * camera_.forward())
            .normalized();
    intensity = lighting.ambient + lighting.diffuse * std::max(0.0, n.dot(l));
  }
  const Rgb colour = shade(facing ? front : back, intensity);

  const double area = (p[1].x - p[0].x) * (p[2].y - p[0].y) - (p[1].y - p[0].y) * (p[2].x - p[0].x);
  if (area == 0 || !std::isfinite(area)) return;
  const double x0 = std::min({p[0].x, p[1].x, p[2].x}), x1 = std::max({p[0].x, p[1].x, p[2].x});
  const double y0 = std::min({p[0].y, p[1].y, p[2].y}), y1 = std::max({p[0].y, p[1].y, p[2].y});
  const int ix0 = std::max(0, static_cast<int>(std::floor(x0 - 0.5)));
  const int ix1 = std::min(w_ - 1, static_cast<int>(std::ceil(x1 - 0.5)));
  const int iy0 = std::max(0, static_cast<int>(std::floor(y0 - 0.5)));
  const int iy1 = std::min(h_ - 1, static_cast<int>(std::ceil(y1 - 0.5)));
  const auto edge = [](const Projected& u, const Projected& v, double x, double y) {
    return (v.x - u.x) * (y - u.y) - (v.y - u.y) * (x - u.x);
  };
  for (int y = iy0; y <= iy1; ++y) {
    const double py = y + 0.5;
    for (int x = ix0; x <= ix1; ++x) {
      const double px = x + 0.5;
      const double w0 = edge(p[1], p[2], px, py) / area;
      const double w1 = edge(p[2], p[0], px, py) / area;
      const double w2 = 1 - w0 - w1;
      if (w0 < 0 || w1 < 0 || w2 < 0) continue;
      const double z = w0 * p[0].inv_depth + w1 * p[1].inv_depth + w2 * p[2].inv_depth;
      const std::size_t i = static_cast<std::size_t>(y) * w_ + x;
      if (z > inv_depth_[i]) {
        inv_depth_[i] = z;
        colour_[i] = colour;
      }
    }
  }
}

void Rasteriser::stamp(double cx, double cy, double inv_depth, double half, bool round,
                       Rgb colour) {
  const int x0 = std::max(0, static_cast<int>(std::floor(cx - half)));
  const int x1 = std::min(w_ - 1, static_cast<int>(std::ceil(cx + half)));
  const int y0 = std::max(0, static_cast<int>(std::floor(cy - half)));
  const int y1 = std::min(h_ - 1, static_cast<int>(std::ceil(cy + half)));
  for (int y = y0; y <= y1; ++y) {
    const double dy = y + 0.5 - cy;
    if (std::abs(dy) > half) continue;
    for (int x = x0; x <= x1; ++x) {
      const double dx = x + 0.5 - cx;
      if (std::abs(dx) > half || (round && dx * dx + dy * dy > half * half)) continue;
      const std::size_t i = static_cast<std::size_t>(y) * w_ + x;
      if (inv_depth >= inv_depth_[i]) {
        inv_depth_[i] = inv_depth;
        colour_[i] = colour;
      }
    }
  }
}

void Rasteriser::line(const Vec3& a, const Vec3& b, Rgb colour, double width_px) {
  // Clip against the near plane in world space.
  const Vec3 f = camera_.forward(), e = camera_.eye();
  Vec3 u = a, v = b;
  const double da = (a - e).dot(f), db = (b - e).dot(f);
  if (da < near_ && db < near_) return;
  if (da < near_) u = a + (near_ - da) / (db - da) * (b - a);
  if (db < near_) v = b + (near_ - db) / (da - db) * (a - b);
  Projected p, q;
  if (!project(u, p) || !project(v, q)) return;
  const double length = std::hypot(q.x - p.x, q.y - p.y);
  if (!std::isfinite(length)) return;
  const double half = std::max(0.5, 0.5 * width_px * ss_);
  const int steps = static_cast<int>(std::min(1e6, std::ceil(length / 0.5))) + 1;
  const double bias = 1 + line_depth_bias;
  for (int k = 0; k <= steps; ++k) {
    const double t = static_cast<double>(k) / steps;
    stamp(p.x + t * (q.x - p.x), p.y + t * (q.y - p.y),
          bias * (p.inv_depth + t * (q.inv_depth - p.inv_depth)), half, false, colour);
  }
}

void Rasteriser::point(const Vec3& p, Rgb colour, double radius_px) {
  Projected s;
  if (!project(p, s)) return;
  stamp(s.x, s.y, (1 + 2 * line_depth_bias) * s.inv_depth, std::max(0.5, radius_px * ss_), true,
        colour);
}

Picture Rasteriser::picture() const {
  Picture out(width_, height_);
  const int n = ss_ * ss_;
  for (int y = 0; y < height_; ++y) {
    for (int x = 0; x < width_; ++x) {
      int r = 0, g = 0, b = 0;
      for (int sy = 0; sy < ss_; ++sy) {
        for (int sx = 0; sx < ss_; ++sx) {
          const Rgb c = colour_[static_cast<std::size_t>(y * ss_ + sy) * w_ + (x * ss_ + sx)];
          r += c.r;
          g += c.g;
          b += c.b;
        }
      }
      out.set(
          x, y,
          {static_cast<std::uint8_t>((r + n / 2) / n), static_cast<std::uint8_t>((g + n / 2) / n),
           static_cast<std::uint8_t>((b + n / 2) / n)});
    }
  }
  return out;
}

}  // namespace crumple::render
