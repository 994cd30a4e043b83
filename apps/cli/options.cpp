#include "options.hpp"

#include <crumple/core/error.hpp>
#include <crumple/geometry/distance.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>

namespace crumple::cli {

namespace {

std::string lower_extension(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

bool is_mesh_file(const std::filesystem::path& p) {
  const std::string ext = lower_extension(p);
  return ext == ".obj" || ext == ".ply" || ext == ".off" || ext == ".x3d";
}

std::string count_text(double n) {
  char buf[32];
  std::snprintf(buf, sizeof buf, n < 1e6 ? "%.0f" : "%.3g", n);
  return buf;
}

/// Inflated bounding boxes overlap (a cheap test before the exact distance).
bool boxes_near(const Vec3& amin, const Vec3& amax, const Vec3& bmin, const Vec3& bmax,
                Scalar gap) {
  return (amin.array() <= bmax.array() + gap).all() && (bmin.array() <= amax.array() + gap).all();
}

/// The exponent k such that 2^k times the largest finite |coordinate| of x lies in [1, 2) (0
/// when every coordinate is 0).
int scale_exponent(PositionsView x) {
  Scalar magnitude = 0;
  for (const Vec3& p : x) {
    for (int a = 0; a < 3; ++a) {
      const Scalar c = std::abs(p[a]);
      if (std::isfinite(c)) magnitude = std::max(magnitude, c);
    }
  }
  return magnitude > 0 ? -std::ilogb(magnitude) : 0;
}

}  // namespace

void add_detection_options(CLI::App& app, DetectionArgs& args, const DetectionHelp& help) {
  app.add_option("-m,--method", args.method,
                 methods_help() + "\nDefault: " + help.method_default);
  auto* thick = app.add_option("-t,--thickness", args.thickness,
                               "Contact thickness h in scene units; default: " +
                                   help.thickness_default);
  app.add_option("-r,--thickness-rel", args.thickness_rel,
                 "Thickness as a fraction of the first frame's bounding-box diagonal")
      ->excludes(thick);
  app.add_option("-k,--kinds", args.kinds,
                 "Contact kinds: comma-separated vf, ee, tt; default vf,ee");
  app.add_option("-j,--threads", args.threads,
                 "Detector threads, 0 (all cores) to " + std::to_string(kMaxThreads))
      ->capture_default_str();
  if (help.max_contacts) {
    app.add_option("--max-contacts", args.max_contacts,
                   "Stop before detecting when the thickness would give more contacts than this "
                   "(estimated; 0 = no limit)")
        ->capture_default_str();
  }
}

std::string methods_help() {
  std::string out = "Detection method SPEC, NAME[:key=value,...]. Methods:";
  for (const MethodInfo& m : all_methods()) {
    out += "\n  " + std::string(m.name) + " — " + std::string(m.summary);
    for (const ParamInfo& p : m.params) {
      out += "\n      " + std::string(p.key) + "=" + std::string(p.default_value) + "  " +
             std::string(p.description);
    }
  }
  return out;
}

MethodSpec method_of(const DetectionArgs& args, std::optional<MethodSpec> fallback) {
  if (args.method) return MethodSpec::parse(*args.method);
  return fallback ? *fallback : MethodSpec::parse(kDefaultMethod);
}

void check_detection_args(const DetectionArgs& args) {
  if (args.threads < 0 || args.threads > kMaxThreads) {
    throw InputError("--threads must be between 0 (all cores) and " +
                     std::to_string(kMaxThreads) + ", got " + std::to_string(args.threads));
  }
  if (args.max_contacts < 0) throw InputError("--max-contacts must be >= 0 (0 = no limit)");
  if (args.thickness_rel && !(std::isfinite(*args.thickness_rel) && *args.thickness_rel >= 0)) {
    throw InputError("--thickness-rel must be a finite number >= 0");
  }
}

Scalar thickness_of(const DetectionArgs& args, PositionsView first, std::optional<Scalar> own) {
  Scalar h = 0;
  if (args.thickness) {
    h = *args.thickness;
  } else if (args.thickness_rel) {
    h = *args.thickness_rel * compute_bounds(first).diagonal();
  } else if (own) {
    h = *own;
  } else {
    h = default_thickness(first);
  }
  if (!(std::isfinite(h) && h >= 0)) throw InputError("--thickness must be a finite number >= 0");
  return h;
}

DetectorOptions detector_options(const DetectionArgs& args, PositionsView first,
                                 std::optional<Scalar> own) {
  check_detection_args(args);
  DetectorOptions options;
  options.threads = args.threads;
  if (args.kinds) options.kinds = ContactKinds::parse(*args.kinds);
  options.thickness = thickness_of(args, first, own);
  return options;
}

void check_contact_budget(const Topology& topo, PositionsView x, const DetectorOptions& options,
                          long long max_contacts) {
  if (x.empty() || topo.num_faces() == 0) return;
  const Scalar h = options.thickness;
  const Scalar diagonal = compute_bounds(x).diagonal();
  if (diagonal > 0 && h > 0.05 * diagonal) {
    std::fprintf(stderr,
                 "crumple: warning: the thickness %.6g is %.3g times the mesh's size (bounding-box "
                 "diagonal %.6g): most pairs of the mesh will be contacts\n",
                 h, h / diagonal, diagonal);
  }
  // Contacts per vertex stay bounded by the input while h is a few edge lengths at most.
  if (max_contacts == 0 || !(h > 4 * edge_length_stats(topo, x).mean)) return;
  // Otherwise count exactly around a sample of vertices and edges and scale up. The count
  // compares squared distances, so it runs on the positions and the thickness times the power
  // of two 2^k that brings the largest coordinate near 1 (exact, as in the detectors):
  // coordinates near 1e200 would overflow (every pair within an infinite h^2), near 1e-200
  // underflow (every pair at distance 0).
  const int k = scale_exponent(x);
  Positions y(x.size());
  for (std::size_t v = 0; v < x.size(); ++v) {
    for (int a = 0; a < 3; ++a) y[v][a] = std::scalbn(x[v][a], k);
  }
  const Scalar hs = std::scalbn(h, k);
  constexpr Index kSamples = 64;
  const auto faces = topo.faces();
  const auto edges = topo.edges();
  std::vector<Vec3> fmin(faces.size()), fmax(faces.size()), emin(edges.size()), emax(edges.size());
  for (std::size_t f = 0; f < faces.size(); ++f) {
    const Vec3 &a = y[static_cast<std::size_t>(faces[f][0])], &b = y[static_cast<std::size_t>(faces[f][1])],
               &c = y[static_cast<std::size_t>(faces[f][2])];
    fmin[f] = a.cwiseMin(b).cwiseMin(c);
    fmax[f] = a.cwiseMax(b).cwiseMax(c);
  }
  for (std::size_t e = 0; e < edges.size(); ++e) {
    const Vec3 &a = y[static_cast<std::size_t>(edges[e][0])], &b = y[static_cast<std::size_t>(edges[e][1])];
    emin[e] = a.cwiseMin(b);
    emax[e] = a.cwiseMax(b);
  }
  double estimate = 0;
  const Scalar h2 = hs * hs;
  if (options.kinds.vf || options.kinds.tt) {
    const Index nv = topo.num_vertices(), step = std::max<Index>(1, nv / kSamples);
    double found = 0, sampled = 0;
    for (Index v = 0; v < nv; v += step, ++sampled) {
      const Vec3& p = y[static_cast<std::size_t>(v)];
      for (std::size_t f = 0; f < faces.size(); ++f) {
        if (!boxes_near(p, p, fmin[f], fmax[f], hs) || topo.face_has_vertex(static_cast<Index>(f), v)) continue;
        const auto& t = faces[f];
        found += geometry::point_triangle(p, y[static_cast<std::size_t>(t[0])], y[static_cast<std::size_t>(t[1])],
                                          y[static_cast<std::size_t>(t[2])])
                     .sqr_distance <= h2;
      }
    }
    estimate += found / sampled * nv;
  }
  if (options.kinds.ee) {
    const Index ne = topo.num_edges(), step = std::max<Index>(1, ne / kSamples);
    double found = 0, sampled = 0;
    for (Index e = 0; e < ne; e += step, ++sampled) {
      const Edge& a = edges[static_cast<std::size_t>(e)];
      for (std::size_t g = 0; g < edges.size(); ++g) {
        const Edge& b = edges[g];
        if (static_cast<Index>(g) == e || a[0] == b[0] || a[0] == b[1] || a[1] == b[0] || a[1] == b[1]) continue;
        if (!boxes_near(emin[static_cast<std::size_t>(e)], emax[static_cast<std::size_t>(e)], emin[g], emax[g], hs)) continue;
        found += geometry::segment_segment(y[static_cast<std::size_t>(a[0])], y[static_cast<std::size_t>(a[1])],
                                           y[static_cast<std::size_t>(b[0])], y[static_cast<std::size_t>(b[1])])
                     .sqr_distance <= h2;
      }
    }
    estimate += found / sampled * ne / 2;  // each pair counted from both of its edges
  }
  if (estimate > static_cast<double>(max_contacts)) {
    char thickness[32];
    std::snprintf(thickness, sizeof thickness, "%.6g", h);
    throw InputError(std::string("the thickness ") + thickness +
                     " would give about " + count_text(estimate) + " contacts on this mesh (" +
                     std::to_string(topo.num_faces()) + " faces), more than --max-contacts " +
                     std::to_string(max_contacts) +
                     ": give a smaller --thickness (the default is 1/" +
                     count_text(1 / kDefaultThicknessRel) +
                     " of the bounding-box diagonal) or raise --max-contacts (0 = no limit)");
  }
}

std::vector<std::filesystem::path> frame_files(const std::vector<std::string>& inputs) {
  std::vector<std::filesystem::path> files;
  for (const std::string& input : inputs) {
    const std::filesystem::path path(input);
    std::error_code ec;
    const auto status = std::filesystem::status(path, ec);
    if (!std::filesystem::exists(status)) {
      throw InputError("no such file or folder: '" + input + "'");
    }
    if (!std::filesystem::is_directory(status)) {
      files.push_back(path);
      continue;
    }
    std::vector<std::filesystem::path> folder;
    for (const auto& entry : std::filesystem::directory_iterator(path)) {
      if (entry.is_regular_file() && is_mesh_file(entry.path())) folder.push_back(entry.path());
    }
    if (folder.empty()) {
      throw InputError("folder '" + input + "' holds no .obj .ply .off .x3d frame");
    }
    std::sort(folder.begin(), folder.end());
    files.insert(files.end(), folder.begin(), folder.end());
  }
  return files;
}

}  // namespace crumple::cli
