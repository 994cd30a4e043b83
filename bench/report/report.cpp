// `crumple bench`'s report (report.hpp). Every method is timed on the same recorded frames and
// compared with `naive` in the same run.
#include "report.hpp"

#include "bench_suite.hpp"
#include "svg_plot.hpp"

#include <crumple/core/atomic_file.hpp>
#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/io/mesh_io.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <variant>
#include <vector>

namespace crumple::bench {
namespace {

// ---------------------------------------------------------------------------------------------
// The thesis' numbers (SPEC.md §4) and the methods of the Figure 4.2 table.

struct Bin {
  const char* label;
  double lo, hi;  ///< share of edges in collision, [lo, hi)
};
/// The thesis' columns, ± 10 points (the 80% column takes everything from 70% up).
constexpr std::array<Bin, 4> kBins{{{"0%", 0.0, 0.10}, {"30%", 0.20, 0.40}, {"50%", 0.40, 0.60},
                                    {"80%", 0.70, 1.01}}};

struct Row {
  const char* label;
  const char* spec;
  std::array<double, 4> thesis_fps;  ///< 0 = not in the thesis
};

constexpr Row kRows[] = {
    {"naive O(n²)", "naive:cull=off", {40, 35, 35, 30}},  // the thesis' loop: every pair tested
    {"stochastic simple, setting 1", "stochastic:variant=simple,setting=1", {550, 130, 40, 10}},
    {"stochastic simple, setting 2", "stochastic:variant=simple,setting=2", {}},
    {"stochastic propagate-by-convergence, setting 1", "stochastic:variant=propagate-by-convergence,setting=1", {}},
    {"stochastic propagate-by-convergence, setting 2", "stochastic:variant=propagate-by-convergence,setting=2", {}},
    {"stochastic direct, setting 1", "stochastic:variant=direct,setting=1", {550, 150, 80, 20}},
    {"stochastic direct, setting 2", "stochastic:variant=direct,setting=2", {550, 210, 200, 130}},
    {"stochastic direct, 400 pairs, no propagation", "stochastic:variant=direct,active=400,propagation=none", {}},
    {"stochastic vertex, setting 1", "stochastic:variant=vertex,setting=1", {550, 150, 80, 50}},
    {"stochastic vertex, setting 2", "stochastic:variant=vertex,setting=2", {550, 320, 290, 190}},
    {"stochastic vertex, 400 pairs, no propagation", "stochastic:variant=vertex,active=400,propagation=none", {}},
    {"k-DOP hierarchy (18-DOP, motion-inflated)", "kdop:sweep=on", {400, 350, 250, 120}},
    {"k-DOP hierarchy, no motion inflation (the default)", "kdop", {}},
    {"k-DOP hierarchy + normal cones (they cull intersection-only queries: same work here)", "kdop:cones=on", {}},
    {"spatial hash", "hash", {}},
    {"sweep and prune", "sap", {}},
};
constexpr std::size_t kNaiveRow = 0;

/// What the thesis says of the >80% frames (Figure 4.3).
const char* thesis_quality(const std::string& spec) {
  if (spec.find("setting=1") != std::string::npos) return "1 pair missed";
  if (spec.find("setting=2") != std::string::npos) return "a few pairs missed";
  if (spec.find("active=400") != std::string::npos) return "1 pair missed (70 fps)";
  return "";
}

// ---------------------------------------------------------------------------------------------
// Result tables: one structure written as CSV, as JSON and (by hand) as markdown.

using Cell = std::variant<std::string, double, long long>;

struct Table {
  std::vector<std::string> columns;
  std::vector<std::vector<Cell>> rows;

  void add(std::vector<Cell> row) {
    CRUMPLE_CHECK(row.size() == columns.size(), "table row width");
    rows.push_back(std::move(row));
  }
  std::string csv() const {
    std::string out;
    for (std::size_t i = 0; i < columns.size(); ++i) out.append(i ? "," : "").append(columns[i]);
    out.push_back('\n');
    for (const auto& row : rows) {
      for (std::size_t i = 0; i < row.size(); ++i) {
        out.append(i ? "," : "");
        if (const auto* s = std::get_if<std::string>(&row[i])) {
          out.append("\"").append(*s).append("\"");  // specs hold commas
        } else if (const auto* d = std::get_if<double>(&row[i])) {
          out.append(std::isfinite(*d) ? json_number(*d) : "");
        } else {
          out.append(std::to_string(std::get<long long>(row[i])));
        }
      }
      out.push_back('\n');
    }
    return out;
  }
  std::string json() const {
    std::string out = "[";
    for (std::size_t r = 0; r < rows.size(); ++r) {
      JsonObject o;
      for (std::size_t i = 0; i < columns.size(); ++i) {
        if (const auto* s = std::get_if<std::string>(&rows[r][i])) {
          o.add(columns[i], std::string_view(*s));
        } else if (const auto* d = std::get_if<double>(&rows[r][i])) {
          o.add(columns[i], *d);
        } else {
          o.add(columns[i], std::get<long long>(rows[r][i]));
        }
      }
      out.append(r ? ",\n " : "").append(o.str());
    }
    return out + "]";
  }
};

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string fixed(double v, int digits) {
  if (!std::isfinite(v)) return "–";
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

/// A frames-per-second figure rounded to 2–3 significant digits, with thousands separators.
std::string fps_text(double fps) {
  if (!std::isfinite(fps)) return "–";
  if (fps < 100) return fixed(fps, fps < 10 ? 1 : 0);
  const double scale = std::pow(10.0, std::floor(std::log10(fps)) - 2);
  long long v = std::llround(std::round(fps / scale) * scale);
  std::string digits = std::to_string(v), out;
  for (std::size_t i = 0; i < digits.size(); ++i) {
    if (i && (digits.size() - i) % 3 == 0) out.push_back(',');
    out.push_back(digits[i]);
  }
  return out;
}

// ---------------------------------------------------------------------------------------------

using Args = ReportOptions;

/// Progress of the run: the sections finished and each step named.
class BenchProgress {
 public:
  explicit BenchProgress(const ReportProgress& report) : report_(report) {}
  void show(const std::string& section, const std::string& label) const {
    if (report_) report_(done_, section, label);
  }
  void section_done() { ++done_; }

 private:
  const ReportProgress& report_;
  std::size_t done_ = 0;
};

/// Aggregates of one method over the frames of one bin.
struct BinFigures {
  std::size_t frames = 0;
  double mean_ms = kNaN;
  double naive_ms = kNaN;
  ContactMatch total;
  std::size_t max_missed = 0;
  double fps() const { return frames ? 1000.0 / mean_ms : kNaN; }
  double ratio() const { return frames ? naive_ms / mean_ms : kNaN; }
  double recall() const { return frames ? total.recall() : kNaN; }
};

BinFigures bin_figures(const Timing& t, const Timing& naive, const std::vector<double>& share, const Bin& bin) {
  BinFigures f;
  double sum = 0, naive_sum = 0;
  for (std::size_t i = 0; i < share.size(); ++i) {
    if (share[i] < bin.lo || share[i] >= bin.hi) continue;
    ++f.frames;
    sum += t.ms[i];
    naive_sum += naive.ms[i];
    if (!t.match.empty()) {
      f.total += t.match[i];
      f.max_missed = std::max(f.max_missed, t.match[i].missed);
    }
  }
  if (f.frames) {
    f.mean_ms = sum / static_cast<double>(f.frames);
    f.naive_ms = naive_sum / static_cast<double>(f.frames);
  }
  return f;
}

ContactMatch sum_matches(const std::vector<ContactMatch>& matches) {
  ContactMatch total;
  for (const ContactMatch& m : matches) total += m;
  return total;
}

double mean(const std::vector<double>& v) {
  if (v.empty()) return kNaN;
  double s = 0;
  for (double x : v) s += x;
  return s / static_cast<double>(v.size());
}

/// Times every row on a recording, interleaved by repetition (`time_methods_against_first`);
/// naive first: its contacts are the reference.
std::vector<Timing> time_rows(const Recording& rec, const std::vector<Row>& rows, ContactKinds kinds,
                              const Args& args, const BenchProgress& progress, const std::string& section) {
  const DetectorOptions options{.thickness = rec.thickness, .kinds = kinds, .threads = args.threads};
  const TimingPlan plan{.first = 0, .timed_from = 0, .last = rec.frames.size(), .repetitions = args.repeat};
  std::vector<std::string> specs;
  for (const Row& row : rows) specs.emplace_back(row.spec);
  return time_methods_against_first(
      rec.mesh.topology_ptr(), rec.frames, specs, options, plan, [&](int rep, std::size_t m) {
        progress.show(section, "run " + std::to_string(rep + 1) + "/" + std::to_string(args.repeat) + ": " +
                                   rows[m].label);
      });
}

struct Report {
  Args args;
  std::string machine, commit, date;
  std::map<std::string, Table> tables;  ///< by file stem
  std::map<std::string, std::string> svgs;  ///< by file stem
  std::string markdown;
  std::vector<std::string> headline;  ///< lines printed at the end
};

// --- Figures 4.2 and 4.3 ---------------------------------------------------------------------

void thesis_section(Report& report, const BenchProgress& progress) {
  const Args& a = report.args;
  const std::string spec = a.quick ? "hanging-cloth:nx=5,ny=5" : "hanging-cloth";
  const std::int64_t frames = a.quick ? 150 : 600;
  progress.show("fig 4.2", "recording " + spec);
  const Recording rec = record_scene(spec, frames, a.seed, [&](std::int64_t k) {
    if (k % 20 == 0) progress.show("fig 4.2", "recording " + spec + " frame " + std::to_string(k));
  });
  const std::vector<Row> rows(std::begin(kRows), std::end(kRows));

  std::string md;
  md.append("## Figure 4.2: frames per second against the share of the surface in collision\n\n");
  std::array<std::size_t, 4> bin_frames{};
  for (std::size_t b = 0; b < kBins.size(); ++b) {
    for (double s : rec.share) bin_frames[b] += s >= kBins[b].lo && s < kBins[b].hi;
  }
  md.append("Scene `").append(rec.spec).append("` (").append(std::to_string(rec.mesh.num_faces()))
      .append(" triangles, ").append(std::to_string(rec.mesh.num_edges())).append(" edges, thickness ")
      .append(fixed(rec.thickness, 4)).append(" m), ").append(std::to_string(rec.frames.size()))
      .append(" recorded frames, binned by the share of edges in collision (VF + EE contacts): ");
  for (std::size_t b = 0; b < kBins.size(); ++b) {
    md.append(b ? ", " : "").append(kBins[b].label).append(" = [").append(fixed(100 * kBins[b].lo, 0))
        .append("%, ").append(fixed(std::min(100.0, 100 * kBins[b].hi), 0)).append("%): ")
        .append(std::to_string(bin_frames[b])).append(" frames");
  }
  md.append(". Every method runs on the same frames in order (previous frame = motion), the runs interleaved "
            "(run r of every method before run r + 1 of any, so a drift of the machine's speed weighs on all alike), ")
      .append(std::to_string(a.threads)).append(" thread(s), median of ").append(std::to_string(a.repeat))
      .append(" runs per frame. Cells: detection frames per second and, after ×, the speed-up over `naive` on "
              "the same frames in the same run; the thesis' figure (Pentium 4, 2003) beside it.\n\n");

  Table fig42{{"table", "method", "spec", "bin", "frames", "mean_ms", "fps", "ratio_to_naive", "recall",
               "missed", "false_contacts", "thesis_fps", "thesis_ratio"},
              {}};
  Table fig43{{"method", "spec", "frames", "naive_pairs_per_frame", "missed_total", "missed_per_frame",
               "missed_max", "recall", "fps", "thesis"},
              {}};
  std::vector<Timing> ee_runs;
  for (const bool ee_only : {true, false}) {
    const ContactKinds kinds = ee_only ? ContactKinds{false, true, false} : ContactKinds{};
    const std::string table = ee_only ? "ee" : "vf+ee";
    const std::vector<Timing> runs = time_rows(rec, rows, kinds, a, progress, "fig 4.2 " + table);
    md.append(ee_only ? "### Edge–edge only (as in the thesis)\n\n" : "### Vertex–face + edge–edge\n\n");
    md.append("| method | recall |");
    for (const Bin& b : kBins) md.append(" ").append(b.label).append(ee_only ? " | thesis |" : " |");
    md.append("\n|---|---|");
    for (std::size_t b = 0; b < kBins.size(); ++b) md.append(ee_only ? "---|---|" : "---|");
    md.append("\n");
    for (std::size_t r = 0; r < rows.size(); ++r) {
      const ContactMatch all = sum_matches(runs[r].match);
      md.append("| ").append(rows[r].label).append(" <br>`").append(rows[r].spec).append("` | ")
          .append(fixed(100 * all.recall(), 2)).append("% |");
      for (std::size_t b = 0; b < kBins.size(); ++b) {
        const BinFigures f = bin_figures(runs[r], runs[kNaiveRow], rec.share, kBins[b]);
        const double thesis = ee_only ? rows[r].thesis_fps[b] : 0;
        const double thesis_ratio = thesis > 0 ? thesis / kRows[kNaiveRow].thesis_fps[b] : kNaN;
        md.append(" ").append(fps_text(f.fps())).append(" ×").append(fixed(f.ratio(), 1)).append(" |");
        if (ee_only) {
          md.append(" ").append(thesis > 0 ? fps_text(thesis) + " ×" + fixed(thesis_ratio, 1) : "").append(" |");
        }
        fig42.add({table, std::string(rows[r].label), std::string(rows[r].spec), std::string(kBins[b].label),
                   static_cast<long long>(f.frames), f.mean_ms, f.fps(), f.ratio(), f.recall(),
                   static_cast<long long>(f.total.missed), static_cast<long long>(f.total.false_contacts),
                   thesis > 0 ? thesis : kNaN, thesis_ratio});
      }
      md.append("\n");
    }
    md.append("\n");
    if (ee_only) ee_runs = runs;
  }

  // Figure 4.3: pairs missed on the frames above 80% (edge–edge, as in the thesis).
  md.append("## Figure 4.3: colliding pairs missed on the frames with ≥ 70% of edges in collision\n\n")
      .append("Edge–edge pairs, against `naive` on the same frames (runs of the table above).\n\n")
      .append("| method | frames | naive pairs / frame | missed / frame | max missed | recall | fps | thesis |\n")
      .append("|---|---|---|---|---|---|---|---|\n");
  const Bin& top = kBins.back();
  for (std::size_t r = 0; r < rows.size(); ++r) {
    if (std::string(rows[r].spec).rfind("stochastic", 0) != 0) continue;
    const BinFigures f = bin_figures(ee_runs[r], ee_runs[kNaiveRow], rec.share, top);
    const double per_frame = f.frames ? static_cast<double>(f.total.reference) / static_cast<double>(f.frames) : kNaN;
    const double missed = f.frames ? static_cast<double>(f.total.missed) / static_cast<double>(f.frames) : kNaN;
    md.append("| ").append(rows[r].label).append(" | ").append(std::to_string(f.frames)).append(" | ")
        .append(fixed(per_frame, 1)).append(" | ").append(fixed(missed, 2)).append(" | ")
        .append(std::to_string(f.max_missed)).append(" | ").append(fixed(100 * f.recall(), 2)).append("% | ")
        .append(fps_text(f.fps())).append(" | ").append(thesis_quality(rows[r].spec)).append(" |\n");
    fig43.add({std::string(rows[r].label), std::string(rows[r].spec), static_cast<long long>(f.frames), per_frame,
               static_cast<long long>(f.total.missed), missed, static_cast<long long>(f.max_missed), f.recall(),
               f.fps(), std::string(thesis_quality(rows[r].spec))});
  }
  md.append("\n");

  // Plots: fps per bin (ours), and the speed-up over naive, ours against the thesis'.
  PlotSpec fps_plot{"Figure 4.2 (edge–edge): detection frames per second", "share of edges in collision",
                    "frames per second", false, true, {}, 860, 500};
  PlotSpec ratio_plot{"Speed-up over naive: crumple (solid) and the thesis (dashed)", "share of edges in collision",
                      "× naive", false, true, {}, 860, 500};
  for (const Bin& b : kBins) {
    fps_plot.x_categories.emplace_back(b.label);
    ratio_plot.x_categories.emplace_back(b.label);
  }
  std::vector<PlotSeries> fps_series, ratio_series;
  for (std::size_t r = 0; r < rows.size(); ++r) {
    const std::string spec_text = rows[r].spec;
    const bool plotted = spec_text.find("propagate-by") == std::string::npos &&
                         spec_text.find("active=400") == std::string::npos && spec_text != "kdop" &&
                         spec_text != "kdop:cones=on";
    if (!plotted) continue;
    PlotSeries ours{rows[r].label, {}, false}, ratio{std::string(rows[r].label), {}, false},
        thesis{std::string("thesis: ") + rows[r].label, {}, true};
    for (std::size_t b = 0; b < kBins.size(); ++b) {
      const BinFigures f = bin_figures(ee_runs[r], ee_runs[kNaiveRow], rec.share, kBins[b]);
      ours.points.emplace_back(static_cast<double>(b), f.fps());
      ratio.points.emplace_back(static_cast<double>(b), f.ratio());
      if (rows[r].thesis_fps[b] > 0) {
        thesis.points.emplace_back(static_cast<double>(b), rows[r].thesis_fps[b] / kRows[kNaiveRow].thesis_fps[b]);
      }
    }
    ours.colour = static_cast<int>(fps_series.size());
    fps_series.push_back(ours);
    if (r != kNaiveRow && !thesis.points.empty()) {
      ratio.colour = thesis.colour = static_cast<int>(ratio_series.size() / 2);
      ratio_series.push_back(ratio);
      ratio_series.push_back(thesis);
    }
  }
  report.svgs["fig42-fps"] = render_svg(fps_plot, fps_series);
  report.svgs["fig42-speedup"] = render_svg(ratio_plot, ratio_series);
  md.append("![fps](fig42-fps.svg)\n\n![speed-up](fig42-speedup.svg)\n\n");

  report.tables["fig42"] = std::move(fig42);
  report.tables["fig43"] = std::move(fig43);
  report.markdown.append(md);

  for (std::size_t r : {std::size_t{6}, std::size_t{9}, std::size_t{11}}) {
    std::string line = std::string(rows[r].label) + ": ×";
    for (std::size_t b = 0; b < kBins.size(); ++b) {
      line.append(b ? ", ×" : "").append(fixed(bin_figures(ee_runs[r], ee_runs[kNaiveRow], rec.share, kBins[b]).ratio(), 1));
    }
    line.append(" naive (thesis ×");
    for (std::size_t b = 0; b < kBins.size(); ++b) {
      line.append(b ? ", ×" : "").append(fixed(rows[r].thesis_fps[b] / kRows[kNaiveRow].thesis_fps[b], 1));
    }
    report.headline.push_back(line + ")");
  }
}

// --- The thesis' second test: a 100×10 strip ---------------------------------------------------

void second_section(Report& report, const BenchProgress& progress) {
  const Args& a = report.args;
  const std::string spec = a.quick ? "hanging-cloth:nx=12,ny=3,size=1.2,depth=0.3"
                                   : "hanging-cloth:nx=100,ny=10,size=2,depth=0.2";
  const std::int64_t frames = a.quick ? 40 : 300;
  const Recording rec = record_scene(spec, frames, a.seed, [&](std::int64_t k) {
    if (k % 20 == 0) progress.show("second test", "recording " + spec + " frame " + std::to_string(k));
  });
  const std::vector<Row> rows = {
      {"naive O(n²)", "naive:cull=off", {}},
      {"stochastic vertex, 300 pairs, no propagation", "stochastic:variant=vertex,active=300,propagation=none", {}},
      {"stochastic direct, 300 pairs, no propagation", "stochastic:variant=direct,active=300,propagation=none", {}},
      {"k-DOP hierarchy", "kdop", {}},
      {"spatial hash", "hash", {}},
      {"sweep and prune", "sap", {}},
  };
  Args once = a;
  once.repeat = 1;  // naive on 2,000 triangles: one run per frame is enough
  const std::vector<Timing> runs =
      time_rows(rec, rows, ContactKinds{false, true, false}, once, progress, "second test");
  const double max_share = *std::max_element(rec.share.begin(), rec.share.end());
  std::string md;
  md.append("## The thesis' second test: a 100×10 lattice\n\nScene `").append(rec.spec).append("` (")
      .append(std::to_string(rec.mesh.num_faces())).append(" triangles), ").append(std::to_string(rec.frames.size()))
      .append(" frames (share of edges in collision up to ").append(fixed(100 * max_share, 0))
      .append("%), edge–edge, one run per frame. The thesis: 300 active pairs without propagation, 40 fps.\n\n")
      .append("| method | mean ms | fps | × naive | recall |\n|---|---|---|---|---|\n");
  Table t{{"method", "spec", "frames", "mean_ms", "fps", "ratio_to_naive", "recall"}, {}};
  const double naive_ms = mean(runs[kNaiveRow].ms);
  for (std::size_t r = 0; r < rows.size(); ++r) {
    const double ms = mean(runs[r].ms);
    const double recall = sum_matches(runs[r].match).recall();
    md.append("| ").append(rows[r].label).append(" <br>`").append(rows[r].spec).append("` | ").append(fixed(ms, 3))
        .append(" | ").append(fps_text(1000 / ms)).append(" | ").append(fixed(naive_ms / ms, 1)).append(" | ")
        .append(fixed(100 * recall, 2)).append("% |\n");
    t.add({std::string(rows[r].label), std::string(rows[r].spec), static_cast<long long>(rec.frames.size()), ms,
           1000 / ms, naive_ms / ms, recall});
  }
  md.append("\n");
  report.markdown.append(md);
  report.tables["second"] = std::move(t);
  report.headline.push_back("second test (" + std::to_string(rec.mesh.num_faces()) + " triangles): vertex, 300 pairs: " +
                            fps_text(1000 / mean(runs[1].ms)) + " fps, recall " +
                            fixed(100 * sum_matches(runs[1].match).recall(), 1) + "% (thesis: 40 fps)");
}

// --- Scaling: lattices and the real meshes ----------------------------------------------------

struct ScalingInput {
  std::string name;
  std::shared_ptr<const Topology> topology;
  std::vector<Positions> frames;
  Scalar thickness = 0;
  TimingPlan plan;
};

const char* const kScalingMethods[][2] = {
    {"naive", "naive:cull=off"},
    {"stochastic vertex, setting 2", "stochastic:variant=vertex,setting=2"},
    {"stochastic direct, setting 2", "stochastic:variant=direct,setting=2"},
    {"stochastic vertex, 1000 pairs + propagation, 10 ms budget",
     "stochastic:variant=vertex,active=1000,propagation=linear,budget=10"},
    {"k-DOP hierarchy", "kdop"},
    {"spatial hash", "hash"},
    {"sweep and prune", "sap"},
};
constexpr Index kNaiveMaxFaces = 4000;

void scaling_section(Report& report, const BenchProgress& progress) {
  const Args& a = report.args;
  std::vector<ScalingInput> inputs;
  std::vector<Index> sizes = a.quick ? std::vector<Index>{6, 12} : std::vector<Index>{10, 30, 100, 300, 1000};
  std::erase_if(sizes, [&](Index n) { return n > a.max_lattice; });
  for (Index n : sizes) {
    progress.show("scaling", "building the " + std::to_string(n) + "×" + std::to_string(n) + " folding lattice");
    const FoldingSequence seq({.n = n, .frames = 16, .seed = a.seed});
    ScalingInput in;
    in.name = "lattice " + std::to_string(n) + "×" + std::to_string(n);
    in.topology = seq.mesh().topology_ptr();
    in.thickness = seq.thickness();
    in.plan = bench::lattice_scaling_plan(n <= 100 ? 6 : (n <= 300 ? 3 : 2), n <= 100 ? a.repeat : 1);
    // The frames before the plan's first are never fed: left empty.
    for (std::size_t i = 0; i < in.plan.last; ++i) {
      in.frames.push_back(i < in.plan.first ? Positions{} : seq.positions(i));
    }
    inputs.push_back(std::move(in));
  }
  struct RealScene {
    const char* name;
    const char* frame0;
    const char* frame1;
  };
  const std::vector<RealScene> real =
      a.quick ? std::vector<RealScene>{{"ipc thick-cloth", "ipc-toolkit-tests/thick-cloth/t0.ply",
                                        "ipc-toolkit-tests/thick-cloth/t1.ply"}}
              : std::vector<RealScene>{
                    {"cloth-funnel", "sample-scalable-ccd/cloth-funnel/frames/227.ply",
                     "sample-scalable-ccd/cloth-funnel/frames/228.ply"},
                    {"armadillo-rollers", "sample-scalable-ccd/armadillo-rollers/frames/326.ply",
                     "sample-scalable-ccd/armadillo-rollers/frames/327.ply"},
                    {"rod-twist", "sample-scalable-ccd/rod-twist/frames/3036.ply",
                     "sample-scalable-ccd/rod-twist/frames/3037.ply"},
                    {"cloth-ball", "sample-scalable-ccd/cloth-ball/frames/cloth_ball92.ply",
                     "sample-scalable-ccd/cloth-ball/frames/cloth_ball93.ply"},
                    {"n-body", "sample-scalable-ccd/n-body-simulation/frames/balls16_18.ply",
                     "sample-scalable-ccd/n-body-simulation/frames/balls16_19.ply"}};
  std::string skipped;
  for (const RealScene& s : real) {
    const std::filesystem::path f0 = std::filesystem::path(a.data) / s.frame0, f1 = std::filesystem::path(a.data) / s.frame1;
    if (!std::filesystem::exists(f0) || !std::filesystem::exists(f1)) {
      skipped.append(skipped.empty() ? "" : ", ").append(s.name);
      continue;
    }
    progress.show("scaling", std::string("reading ") + s.name);
    const TriMesh m0 = io::read_mesh(f0), m1 = io::read_mesh(f1);
    ScalingInput in;
    in.name = s.name;
    in.topology = m0.topology_ptr();
    in.thickness = default_thickness(m0.positions());
    in.frames = {m0.positions(), m1.positions()};
    in.plan = bench::frame_pair_plan(a.repeat);
    inputs.push_back(std::move(in));
  }

  Table t{{"input", "triangles", "method", "spec", "frames", "mean_ms", "recall", "contacts_per_frame",
           "distance_evals_per_frame"},
          {}};
  std::string md;
  md.append("## Scaling: time per frame against the number of triangles\n\n")
      .append("Folding lattices (`FoldingSequence`: an n×n sheet folded onto itself with a travelling ripple, "
              "thickness ℓ/4; frames 8.. timed after two warm-up frames; median of ")
      .append(std::to_string(a.repeat))
      .append(" runs up to 100×100, one run above) and the real meshes of `../shared/data` (the second frame with "
              "the motion from the first, after an untimed update on the first; h = 1e-3 × diagonal; median of ")
      .append(std::to_string(a.repeat)).append(" runs). VF + EE, ").append(std::to_string(a.threads))
      .append(" thread(s). Methods timed interleaved by run (run r of each before run r + 1 of any). `naive` only "
              "up to ")
      .append(std::to_string(kNaiveMaxFaces))
      .append(" triangles. Recall against the exact `kdop` contacts (equal to naive's, see the tests).");
  if (!skipped.empty()) md.append(" Not found under `").append(a.data).append("`, skipped: ").append(skipped).append(".");
  md.append(" The stochastic rows also give their distance evaluations per frame: the work the parameters "
            "fix, whatever the mesh size.\n\n| input | triangles | method | ms / frame | recall | contacts | "
            "distance evals |\n|---|---|---|---|---|---|---|\n");

  std::map<std::string, PlotSeries> series;
  for (ScalingInput& in : inputs) {
    const DetectorOptions options{.thickness = in.thickness, .kinds = {}, .threads = a.threads};
    const Index faces = in.topology->num_faces();
    // The rows' methods, `kdop` first: its contacts are the reference (exact, equal to naive's).
    std::vector<std::size_t> rows;  // indices into kScalingMethods, in timing order
    for (std::size_t m = 0; m < std::size(kScalingMethods); ++m) {
      const std::string method = kScalingMethods[m][1];
      if (method.starts_with("naive") && faces > kNaiveMaxFaces) continue;
      if (method == "kdop") {
        rows.insert(rows.begin(), m);
      } else {
        rows.push_back(m);
      }
    }
    CRUMPLE_CHECK(std::string(kScalingMethods[rows.front()][1]) == "kdop", "kdop is a scaling method");
    std::vector<std::string> specs;
    for (std::size_t m : rows) specs.emplace_back(kScalingMethods[m][1]);
    const std::vector<Timing> timings = time_methods_against_first(
        in.topology, in.frames, specs, options, in.plan, [&](int rep, std::size_t i) {
          progress.show("scaling", in.name + ", run " + std::to_string(rep + 1) + "/" +
                                       std::to_string(in.plan.repetitions) + ": " + kScalingMethods[rows[i]][0]);
        });
    for (std::size_t m = 0; m < std::size(kScalingMethods); ++m) {
      const auto at = std::find(rows.begin(), rows.end(), m);
      if (at == rows.end()) continue;
      const Timing& timing = timings[static_cast<std::size_t>(at - rows.begin())];
      const char* label = kScalingMethods[m][0];
      const double ms = mean(timing.ms);
      const ContactMatch all = sum_matches(timing.match);
      const double contacts = static_cast<double>(all.reference) / static_cast<double>(timing.ms.size());
      md.append("| ").append(in.name).append(" | ").append(std::to_string(faces)).append(" | ").append(label)
          .append(" | ").append(fixed(ms, ms < 1 ? 3 : 1)).append(" | ").append(fixed(100 * all.recall(), 2))
          .append("% | ").append(fixed(contacts, 0)).append(" | ")
          .append(timing.distance_evals > 0 ? fixed(timing.distance_evals, 0) : "").append(" |\n");
      t.add({in.name, static_cast<long long>(faces), std::string(label), timing.spec,
             static_cast<long long>(timing.ms.size()), ms, all.recall(), contacts,
             timing.distance_evals > 0 ? timing.distance_evals : kNaN});
      if (in.name.rfind("lattice", 0) == 0) {
        PlotSeries& s = series[label];
        s.label = label;
        s.points.emplace_back(static_cast<double>(faces), ms);
      }
    }
  }
  md.append("\n![scaling](scaling.svg)\n\n");
  std::vector<PlotSeries> plot;
  for (const auto& m : kScalingMethods) {
    if (series.count(m[0])) plot.push_back(series[m[0]]);
  }
  report.svgs["scaling"] = render_svg(
      {"Time per frame on folding lattices (VF + EE, " + std::to_string(a.threads) + " thread)", "triangles",
       "ms per frame", true, true, {}, 860, 500},
      plot);
  report.markdown.append(md);
  report.tables["scaling"] = std::move(t);
}

// --- Time budget: recall against time per frame ----------------------------------------------

void budget_section(Report& report, const BenchProgress& progress, const Recording& rec) {
  const Args& a = report.args;
  const std::vector<long long> actives =
      a.quick ? std::vector<long long>{10, 100} : std::vector<long long>{5, 10, 20, 50, 100, 200, 400, 1000, 3000};
  const DetectorOptions options{.thickness = rec.thickness, .kinds = ContactKinds{false, true, false},
                                .threads = a.threads};
  struct Family {
    const char* variant;
    const char* propagation;
    std::vector<std::pair<long long, double>> points;  ///< (active, budget ms)
  };
  std::vector<Family> families;
  for (const char* variant : {"direct", "vertex"}) {
    for (const char* propagation : {"none", "linear"}) {
      Family f{variant, propagation, {}};
      for (long long n : actives) f.points.emplace_back(n, 0.0);
      families.push_back(f);
    }
  }
  {
    Family f{"vertex", "linear", {}};
    const std::vector<double> budgets =
        a.quick ? std::vector<double>{0.05, 1} : std::vector<double>{0.02, 0.05, 0.1, 0.2, 0.5, 1, 2};
    for (double ms : budgets) f.points.emplace_back(1000, ms);
    families.push_back(f);
  }
  const auto spec_of = [](const Family& fam, long long n, double budget) {
    std::string spec = std::string("stochastic:variant=") + fam.variant + ",active=" + std::to_string(n) +
                       ",propagation=" + fam.propagation;
    if (budget > 0) spec.append(",budget=").append(json_number(budget));
    return spec;
  };
  // Every configuration timed on the same frames, interleaved by run; naive first (the reference).
  std::vector<std::string> specs{"naive", "kdop"};
  for (const Family& fam : families) {
    for (const auto& [n, budget] : fam.points) specs.push_back(spec_of(fam, n, budget));
  }
  const TimingPlan plan{.first = 0, .timed_from = 0, .last = rec.frames.size(), .repetitions = a.repeat};
  const std::vector<Timing> timings = time_methods_against_first(
      rec.mesh.topology_ptr(), rec.frames, specs, options, plan, [&](int rep, std::size_t m) {
        progress.show("budget", "run " + std::to_string(rep + 1) + "/" + std::to_string(a.repeat) + ": " + specs[m]);
      });
  const Timing& naive = timings[0];
  const Timing& kdop = timings[1];
  std::size_t next = 2;  // the first stochastic configuration's timing

  Table t{{"variant", "propagation", "active", "budget_ms", "bin", "frames", "mean_ms", "recall", "missed_per_frame"},
          {}};
  std::string md;
  md.append("## Time budget: the stochastic detector's recall against its time per frame\n\n")
      .append("The Figure 4.2 frames (edge–edge), ")
      .append(std::to_string(a.threads))
      .append(" thread(s), `stochastic:variant=V,active=N,propagation=P` for N in ");
  for (std::size_t i = 0; i < actives.size(); ++i) md.append(i ? ", " : "").append(std::to_string(actives[i]));
  md.append(", and the time budget `budget=B` (ms per frame) with 1000 active pairs and linear propagation: "
            "the detector stops drawing and propagating when B is spent. Each point is one bin's mean time per "
            "frame and recall over its frames; the plot shows the 30% (dashed) and 80% (solid) bins, and the exact "
            "`naive` and `kdop` for scale. All of them run on the same frames, interleaved by run (run r of each "
            "before run r + 1 of any), median of ")
      .append(std::to_string(a.repeat))
      .append(" runs per frame.\n\n")
      .append("| variant | propagation | active | budget ms |");
  for (std::size_t b = 1; b < kBins.size(); ++b) md.append(" ").append(kBins[b].label).append(" ms | recall |");
  md.append("\n|---|---|---|---|");
  for (std::size_t b = 1; b < kBins.size(); ++b) md.append("---|---|");
  md.append("\n");
  std::vector<PlotSeries> plot;
  constexpr std::size_t kPlotBins[] = {1, 3};  // 30% and 80%
  for (std::size_t fi = 0; fi < families.size(); ++fi) {
    const Family& fam = families[fi];
    const bool budgeted = fam.points.front().second > 0;
    std::vector<PlotSeries> per_bin(kBins.size());
    for (const auto& [n, budget] : fam.points) {
      const Timing& timing = timings[next++];
      md.append("| ").append(fam.variant).append(" | ").append(fam.propagation).append(" | ")
          .append(std::to_string(n)).append(" | ").append(budget > 0 ? json_number(budget) : "–").append(" |");
      for (std::size_t b = 1; b < kBins.size(); ++b) {
        const BinFigures f = bin_figures(timing, naive, rec.share, kBins[b]);
        md.append(" ").append(fixed(f.mean_ms, 3)).append(" | ").append(fixed(100 * f.recall(), 1)).append("% |");
        t.add({std::string(fam.variant), std::string(fam.propagation), n, budget > 0 ? budget : kNaN,
               std::string(kBins[b].label), static_cast<long long>(f.frames), f.mean_ms, f.recall(),
               f.frames ? static_cast<double>(f.total.missed) / static_cast<double>(f.frames) : kNaN});
        per_bin[b].label = std::string(fam.variant) + ", propagation " + fam.propagation +
                           (budgeted ? ", 1000 pairs, budget" : ", active pairs") + ", " + kBins[b].label;
        per_bin[b].dashed = b == 1;
        per_bin[b].colour = static_cast<int>(fi);
        per_bin[b].points.emplace_back(f.mean_ms, f.recall());
      }
      md.append("\n");
    }
    for (std::size_t b : kPlotBins) plot.push_back(per_bin[b]);
  }
  for (const auto& [label, timing] : {std::pair<const char*, const Timing*>{"naive (exact)", &naive},
                                      std::pair<const char*, const Timing*>{"kdop (exact)", &kdop}}) {
    PlotSeries point{label, {}, false, timing == &naive ? 10 : 7};
    for (std::size_t b : kPlotBins) point.points.emplace_back(bin_figures(*timing, naive, rec.share, kBins[b]).mean_ms, 1.0);
    plot.push_back(point);
  }
  md.append("\n![budget](budget.svg)\n\n");
  report.svgs["budget"] = render_svg({"Stochastic detector: recall against time per frame (edge–edge)",
                                      "ms per frame", "recall", true, false, {}, 900, 520},
                                     plot);
  report.markdown.append(md);
  report.tables["budget"] = std::move(t);
}

// ---------------------------------------------------------------------------------------------

void write_files(const Report& r, const std::filesystem::path& out) {
  const auto write_text = [&](const std::string& name, const std::string& text) {
    write_file_atomically(out / name, [&](std::ostream& s) { s << text; });
  };
  std::string md;
  md.append("# crumple bench: the thesis' Figures 4.2 and 4.3, and beyond\n\n")
      .append("Generated by `crumple bench")
      .append(r.args.quick ? " --quick" : "")
      .append("` (do not edit: rerun it; see README.md here for the discussion).\n\n")
      .append("- machine: ").append(r.machine).append("\n- commit: `").append(r.commit).append("`\n- date: ")
      .append(r.date).append("\n- threads per detector: ").append(std::to_string(r.args.threads))
      .append("\n\n").append(r.markdown);
  std::string json = JsonObject()
                         .add("machine", std::string_view(r.machine))
                         .add("commit", std::string_view(r.commit))
                         .add("date", std::string_view(r.date))
                         .add("quick", r.args.quick)
                         .add("threads", r.args.threads)
                         .add("repeat", r.args.repeat)
                         .str();
  json.pop_back();  // reopen the object to append the tables
  for (const auto& [name, table] : r.tables) {
    json.append(",\n\"").append(name).append("\":").append(table.json());
    write_text(name + ".csv", table.csv());
  }
  json.append("}\n");
  for (const auto& [name, svg] : r.svgs) write_text(name + ".svg", svg);
  write_text("bench.json", json);
  write_text("bench.md", md);
}

}  // namespace

ReportResult write_report(const ReportOptions& options, const std::filesystem::path& out,
                          const ReportProgress& report_progress) {
  Report report;
  report.args = options;
  if (report.args.sections.empty()) report.args.sections.assign(kReportSections.begin(), kReportSections.end());
  const auto wants = [&](const char* s) {
    return std::find(report.args.sections.begin(), report.args.sections.end(), s) != report.args.sections.end();
  };
  report.machine = machine_description();
  report.commit = source_commit();
  report.date = utc_now();
  BenchProgress progress(report_progress);
  if (wants("thesis")) {
    thesis_section(report, progress);
    progress.section_done();
  }
  if (wants("second")) {
    second_section(report, progress);
    progress.section_done();
  }
  if (wants("scaling")) {
    scaling_section(report, progress);
    progress.section_done();
  }
  if (wants("budget")) {
    const std::string spec = options.quick ? "hanging-cloth:nx=5,ny=5" : "hanging-cloth";
    progress.show("budget", "recording " + spec);
    budget_section(report, progress, record_scene(spec, options.quick ? 150 : 600, options.seed));
  }
  write_files(report, out);
  return {report.machine, report.commit, report.headline, report.tables.size(), report.svgs.size()};
}

}  // namespace crumple::bench
