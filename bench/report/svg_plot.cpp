// SVG line charts for the benchmark report (see svg_plot.hpp).
#include "svg_plot.hpp"


#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>

namespace crumple::bench {
namespace {

constexpr std::array<const char*, 12> kColours = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e",
                                                  "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
                                                  "#bcbd22", "#17becf", "#000000", "#aec7e8"};

std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f", v);
  return buf;
}

/// A tick label: plain for moderate values, k/M suffixes for large ones.
std::string tick_label(double v) {
  char buf[32];
  const double a = std::abs(v);
  if (a >= 1e6 && std::fmod(a, 1e6) == 0) {
    std::snprintf(buf, sizeof buf, "%gM", v / 1e6);
  } else if (a >= 1e4 && std::fmod(a, 1e3) == 0) {
    std::snprintf(buf, sizeof buf, "%gk", v / 1e3);
  } else {
    std::snprintf(buf, sizeof buf, "%g", v);
  }
  return buf;
}

std::string escape(const std::string& text) {
  std::string out;
  for (char c : text) {
    switch (c) {
      case '<': out.append("&lt;"); break;
      case '>': out.append("&gt;"); break;
      case '&': out.append("&amp;"); break;
      case '"': out.append("&quot;"); break;
      default: out.push_back(c);
    }
  }
  return out;
}

struct Axis {
  bool log = false;
  double lo = 0, hi = 1;  // in axis units (log10 of the value on a log axis)
  std::vector<double> ticks;  // values (not axis units)

  double unit(double v) const { return log ? std::log10(v) : v; }
  bool drawable(double v) const { return std::isfinite(v) && (!log || v > 0); }
};

/// Axis range and ticks covering [lo, hi] (values), decades on a log axis, 1-2-5 steps otherwise.
Axis make_axis(double lo, double hi, bool log) {
  Axis a;
  a.log = log;
  if (log) {
    a.lo = std::floor(std::log10(lo));
    a.hi = std::ceil(std::log10(hi));
    if (a.hi <= a.lo) a.hi = a.lo + 1;
    for (double e = a.lo; e <= a.hi + 1e-9; e += 1) a.ticks.push_back(std::pow(10.0, e));
    return a;
  }
  if (hi <= lo) {
    hi = lo + (lo == 0 ? 1 : std::abs(lo));
  }
  const double raw = (hi - lo) / 6;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  double step = mag;
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (m * mag >= raw) {
      step = m * mag;
      break;
    }
  }
  a.lo = std::floor(lo / step) * step;
  a.hi = std::ceil(hi / step) * step;
  for (double t = a.lo; t <= a.hi + step * 1e-9; t += step) a.ticks.push_back(std::abs(t) < step * 1e-9 ? 0 : t);
  return a;
}

}  // namespace

std::string render_svg(const PlotSpec& spec, const std::vector<PlotSeries>& series) {
  std::size_t longest = 0;
  for (const auto& s : series) longest = std::max(longest, s.label.size());
  const double left = 80, top = 44, bottom = 60;
  const double right = 60 + 6.4 * static_cast<double>(longest);
  const double w = spec.width + right - 40, h = spec.height;
  const double pw = w - left - right, ph = h - top - bottom;
  const bool categorical = !spec.x_categories.empty();

  double xlo = std::numeric_limits<double>::infinity(), xhi = -xlo, ylo = xlo, yhi = -xlo;
  Axis probe_x, probe_y;
  probe_x.log = spec.log_x && !categorical;
  probe_y.log = spec.log_y;
  for (const auto& s : series) {
    for (const auto& [x, y] : s.points) {
      if (!probe_x.drawable(x) || !probe_y.drawable(y)) continue;
      xlo = std::min(xlo, x);
      xhi = std::max(xhi, x);
      ylo = std::min(ylo, y);
      yhi = std::max(yhi, y);
    }
  }
  const bool empty = !(xlo <= xhi);

  std::string out;
  out.append("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"").append(fmt(w)).append("\" height=\"")
      .append(fmt(h)).append("\" viewBox=\"0 0 ").append(fmt(w)).append(" ").append(fmt(h))
      .append("\" font-family=\"sans-serif\" font-size=\"12\">\n");
  out.append("<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n");
  out.append("<text x=\"").append(fmt(left + pw / 2)).append("\" y=\"24\" text-anchor=\"middle\" font-size=\"15\">")
      .append(escape(spec.title)).append("</text>\n");
  if (empty) {
    out.append("<text x=\"").append(fmt(left + pw / 2)).append("\" y=\"").append(fmt(top + ph / 2))
        .append("\" text-anchor=\"middle\">no data</text>\n</svg>\n");
    return out;
  }

  Axis ax;
  if (categorical) {
    ax.lo = -0.5;
    ax.hi = static_cast<double>(spec.x_categories.size()) - 0.5;
  } else {
    ax = make_axis(xlo, xhi, spec.log_x);
  }
  const Axis ay = make_axis(spec.log_y ? ylo : std::min(ylo, 0.0), yhi, spec.log_y);
  const auto px = [&](double x) { return left + (ax.unit(x) - ax.lo) / (ax.hi - ax.lo) * pw; };
  const auto py = [&](double y) { return top + ph - (ay.unit(y) - ay.lo) / (ay.hi - ay.lo) * ph; };

  // Frame, grid and ticks.
  out.append("<rect x=\"").append(fmt(left)).append("\" y=\"").append(fmt(top)).append("\" width=\"")
      .append(fmt(pw)).append("\" height=\"").append(fmt(ph)).append("\" fill=\"none\" stroke=\"#444\"/>\n");
  for (double t : ay.ticks) {
    const double y = py(t);
    out.append("<line x1=\"").append(fmt(left)).append("\" x2=\"").append(fmt(left + pw)).append("\" y1=\"")
        .append(fmt(y)).append("\" y2=\"").append(fmt(y)).append("\" stroke=\"#ddd\"/>\n");
    out.append("<text x=\"").append(fmt(left - 6)).append("\" y=\"").append(fmt(y + 4))
        .append("\" text-anchor=\"end\">").append(escape(tick_label(t))).append("</text>\n");
  }
  const auto x_tick = [&](double x, const std::string& label) {
    out.append("<line x1=\"").append(fmt(x)).append("\" x2=\"").append(fmt(x)).append("\" y1=\"")
        .append(fmt(top)).append("\" y2=\"").append(fmt(top + ph)).append("\" stroke=\"#ddd\"/>\n");
    out.append("<text x=\"").append(fmt(x)).append("\" y=\"").append(fmt(top + ph + 18))
        .append("\" text-anchor=\"middle\">").append(escape(label)).append("</text>\n");
  };
  if (categorical) {
    for (std::size_t i = 0; i < spec.x_categories.size(); ++i) {
      x_tick(px(static_cast<double>(i)), spec.x_categories[i]);
    }
  } else {
    for (double t : ax.ticks) x_tick(px(t), tick_label(t));
  }
  out.append("<text x=\"").append(fmt(left + pw / 2)).append("\" y=\"").append(fmt(h - 16))
      .append("\" text-anchor=\"middle\">").append(escape(spec.x_label)).append("</text>\n");
  out.append("<text transform=\"translate(18,").append(fmt(top + ph / 2))
      .append(") rotate(-90)\" text-anchor=\"middle\">").append(escape(spec.y_label)).append("</text>\n");

  // Series and legend.
  for (std::size_t i = 0; i < series.size(); ++i) {
    const PlotSeries& s = series[i];
    const std::size_t c = s.colour >= 0 ? static_cast<std::size_t>(s.colour) : i;
    const std::string colour = kColours[c % kColours.size()];
    const bool dashed = s.dashed || c >= kColours.size();
    std::string path;
    for (const auto& [x, y] : s.points) {
      if (!ax.drawable(x) || !ay.drawable(y)) continue;
      path.append(path.empty() ? "" : " ").append(fmt(px(x))).append(",").append(fmt(py(y)));
      out.append("<circle cx=\"").append(fmt(px(x))).append("\" cy=\"").append(fmt(py(y)))
          .append("\" r=\"3\" fill=\"").append(colour).append("\"/>\n");
    }
    if (!path.empty()) {
      out.append("<polyline fill=\"none\" stroke=\"").append(colour).append("\" stroke-width=\"1.8\"")
          .append(dashed ? " stroke-dasharray=\"6,3\"" : "").append(" points=\"").append(path)
          .append("\"/>\n");
    }
    const double ly = top + 8 + 17 * static_cast<double>(i);
    out.append("<line x1=\"").append(fmt(left + pw + 12)).append("\" x2=\"").append(fmt(left + pw + 36))
        .append("\" y1=\"").append(fmt(ly)).append("\" y2=\"").append(fmt(ly)).append("\" stroke=\"")
        .append(colour).append("\" stroke-width=\"2\"").append(dashed ? " stroke-dasharray=\"6,3\"" : "")
        .append("/>\n");
    out.append("<text x=\"").append(fmt(left + pw + 42)).append("\" y=\"").append(fmt(ly + 4)).append("\">")
        .append(escape(s.label)).append("</text>\n");
  }
  out.append("</svg>\n");
  return out;
}

}  // namespace crumple::bench
