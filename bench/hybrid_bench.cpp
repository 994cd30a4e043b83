// Recall against a per-frame time budget: the hybrid detector (docs/hybrid.md), the stochastic
// detector, and the exact `kdop` cut off when the budget is spent (`kdop:budget=B`, the naive way
// to keep a budget) and the hybrid's exhaustive zone search cut off alike, on recorded scenes
// and seeded folding sheets, against the exact `kdop` (one thread) on the same frames.
//
// The budget of a scene is a multiple (0.25, 0.5, 1, 2, 8, 32) of kdop's mean processor time per
// frame on that scene, measured in the same run (frames after the first; the lesser of two runs
// frame by frame). Per method: recall (found / reference contacts over all
// frames), recall of the reference contacts closer than h/4, the worst frame's recall, the mean
// and 99th-percentile time per frame, the p99 over the budget, and false contacts (always 0:
// checked on every frame); the times are those of the frames after the first (which builds
// every method's structures once). Writes hybrid.md, hybrid.csv and one hybrid-<scene>.svg per scene.
//
//   build/release/bench/hybrid_bench --out docs/benchmarks            # every scene
//   build/release/bench/hybrid_bench --quick --out /tmp/h             # two small scenes
//   build/release/bench/hybrid_bench --scenes folding-24,hanging-cloth
//   build/release/bench/hybrid_bench --clock cpu ... # budgets in processor time (clock=cpu)
//   build/release/bench/hybrid_bench --only kdop ... # only the budgeted families whose spec
//                                                   # starts with "kdop", no unbudgeted rows
//                                                   # (a comma list; "hybrid$": that spec only)
//   build/release/bench/hybrid_bench --lean ...     # fewer rows: no thesis-rule, every=4, 64-face
//                                                   # exact zones; budgets 0.25-8 x kdop
//   build/release/bench/hybrid_bench --per-frame ... # each frame's budget is the fraction of
//                                                   # kdop's time on that frame (Detector::
//                                                   # set_budget); writes hybrid-per-frame.{md,csv}
//                                                   # and hybrid-per-frame-<scene>.svg
//   build/release/bench/hybrid_bench --why ...      # stderr: the stage times of the frames
//                                                   # over 1.1 x their budget
//
// kdop is run again after the budgeted runs (reported, with the load average at both times: on
// a shared machine the unit of the budgets drifts). The budgets are wall-clock deadlines; the
// tables give each frame's wall-clock and processor time (the thread's: without the time it was
// descheduled), so that p99 can be read both ways.
#include <crumple/core/json.hpp>
#include <crumple/detect/compare.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/sim/scene.hpp>
#include <report/svg_plot.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace crumple {
namespace {

struct Scene {
  std::string name;
  std::string description;
  std::unique_ptr<FrameSource> frames;
  Scalar h = 0;
};

/// Frames [first, last) of a recording as a frame source.
std::unique_ptr<FrameSource> slice(sim::Recording r, std::size_t first, std::size_t last) {
  last = std::min(last, r.frames.size());
  std::vector<Positions> kept(r.frames.begin() + static_cast<std::ptrdiff_t>(first),
                              r.frames.begin() + static_cast<std::ptrdiff_t>(last));
  return std::make_unique<VectorFrames>(std::move(r.mesh), std::move(kept), r.spec);
}

Scene folding(Index n, std::size_t frames, std::size_t first) {
  const FoldingSequence seq({.n = n, .frames = frames, .seed = 1});
  std::vector<Positions> kept;
  for (std::size_t i = first; i < frames; ++i) kept.push_back(seq.positions(i));
  Scene s;
  s.name = "folding-" + std::to_string(n);
  s.description = "folding sheet " + std::to_string(n) + "x" + std::to_string(n) + " (" +
                  std::to_string(seq.mesh().num_faces()) + " triangles), frames " + std::to_string(first) + "-" +
                  std::to_string(frames - 1) + " of " + std::to_string(frames) + ", seed 1, h = l/4";
  s.h = seq.thickness();
  s.frames = std::make_unique<VectorFrames>(seq.mesh(), std::move(kept), s.name);
  return s;
}

Scene recorded(const std::string& name, const std::string& spec, std::size_t frames, std::size_t first) {
  sim::Recording r = sim::record_scene(spec, static_cast<std::int64_t>(frames), 1);
  Scene s;
  s.name = name;
  s.h = r.thickness;
  s.description = "`" + r.spec + "` (" + std::to_string(r.mesh.num_faces()) + " triangles), frames " +
                  std::to_string(first) + "-" + std::to_string(frames) + ", seed 1";
  s.frames = slice(std::move(r), first, frames + 1);
  return s;
}

Scene make_scene(const std::string& name, bool quick) {
  if (name == "folding-24") return folding(24, quick ? 30 : 60, 0);
  if (name == "folding-100") return folding(100, 32, quick ? 28 : 12);
  if (name == "folding-300") return folding(300, 32, quick ? 30 : 20);
  if (name == "hanging-cloth") return recorded(name, "hanging-cloth", quick ? 150 : 600, quick ? 100 : 100);
  if (name == "strip") return recorded(name, "hanging-cloth:nx=100,ny=10,size=2,depth=0.2", quick ? 60 : 300, 0);
  if (name == "cloth-on-sphere-64") return recorded(name, "cloth-on-sphere:n=64", quick ? 40 : 240, quick ? 20 : 40);
  if (name == "crumple-64") return recorded(name, "crumple:n=64", quick ? 40 : 300, quick ? 20 : 100);
  if (name == "crumple-100") return recorded(name, "crumple:n=100", quick ? 40 : 200, quick ? 20 : 100);
  throw std::runtime_error("unknown scene " + name);
}

using Clock = std::chrono::steady_clock;

struct Run {
  std::string label, spec;
  double fraction = 0;  ///< budget / kdop mean, 0 = none
  double budget_ms = 0;
  ContactMatch total;
  std::size_t close = 0, close_found = 0;
  double worst = 1, mean_ms = 0, p99_ms = 0;
  double cpu_mean_ms = 0, cpu_p99_ms = 0;  ///< the thread's processor time (not descheduled time)
  double cpu_p99_over = 0;  ///< p99 over the frames of each frame's processor time / its budget
  double p99_over = 0;      ///< the same, wall-clock time
  double cpu_p90_over = 0;  ///< the 90th percentile of each frame's processor time / its budget
  double zones_left = 0;  ///< frames where a due zone was left (hybrid)
};

/// This thread's processor time in ms: what a frame costs without the time the scheduler took.
double thread_cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e3 + static_cast<double>(t.tv_nsec) * 1e-6;
}

double mean(const std::vector<double>& v) {
  double sum = 0;
  for (double t : v) sum += t;
  return v.empty() ? 0 : sum / static_cast<double>(v.size());
}

/// The q-quantile (nearest rank) of v.
double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
  return v[std::min(v.size(), std::max<std::size_t>(rank, 1)) - 1];
}

double p99(std::vector<double> v) { return percentile(std::move(v), 0.99); }

bool contains(const ContactSet& got, const VertexFaceContact& c) {
  return std::binary_search(got.vf.begin(), got.vf.end(), c, CanonicalLess{});
}
bool contains(const ContactSet& got, const EdgeEdgeContact& c) {
  return std::binary_search(got.ee.begin(), got.ee.end(), c, CanonicalLess{});
}

/// Where the frames over 1.1 x their budget spent their time: the detector's `*_ms` counters
/// summed over those frames (`--why`, printed to stderr).
struct Overruns {
  std::size_t frames = 0;
  double cpu_ms = 0, budget_ms = 0;
  DetectorStats ms;
};

/// Runs `spec` on every frame (previous positions as motion), against the reference contacts.
/// With `budgets` (one per frame), frame i runs under budget budgets[i] (`Detector::set_budget`).
Run run(const Scene& s, const std::string& spec, const std::vector<ContactSet>& ref,
        std::vector<double>* cpu_times = nullptr, const std::vector<double>& budgets = {},
        Overruns* overruns = nullptr, double budget_ms = 0) {
  auto d = make_detector(MethodSpec::parse(spec), {.thickness = s.h, .threads = 1});
  d->set_topology(s.frames->mesh().topology_ptr());
  Run r;
  r.spec = spec;
  std::vector<double> ms, cpu;
  Positions previous;
  ContactSet got;
  const Scalar close2 = s.h / 4;
  for (std::size_t i = 0; i < s.frames->size(); ++i) {
    const Positions x = s.frames->positions(i);
    if (!budgets.empty()) {
      budget_ms = budgets[i];
      d->set_budget(budget_ms);
    }
    const double c0 = thread_cpu_ms();
    const auto t0 = Clock::now();
    d->update(previous.empty() ? PositionsView{} : PositionsView(previous), x, got);
    ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
    cpu.push_back(thread_cpu_ms() - c0);
    if (overruns && i > 0 && budget_ms > 0 && cpu.back() > 1.1 * budget_ms) {
      ++overruns->frames;
      overruns->cpu_ms += cpu.back();
      overruns->budget_ms += budget_ms;
      for (const auto& [key, value] : d->stats().items()) {
        if (key.ends_with("_ms")) overruns->ms.add(key, value);
      }
    }
    if (!ref.empty()) {
      const ContactMatch m = match_contacts(got, ref[i]);
      if (m.false_contacts > 0) {
        std::fprintf(stderr, "FALSE CONTACTS: %s frame %zu: %zu\n", spec.c_str(), i, m.false_contacts);
      }
      r.total += m;
      r.worst = std::min(r.worst, m.recall());
      for (const auto& c : ref[i].vf) {
        if (c.distance < close2) {
          ++r.close;
          r.close_found += contains(got, c) ? 1 : 0;
        }
      }
      for (const auto& c : ref[i].ee) {
        if (c.distance < close2) {
          ++r.close;
          r.close_found += contains(got, c) ? 1 : 0;
        }
      }
    }
    r.zones_left += d->stats().get("zones_due_left") > 0 ? 1 : 0;
    previous = x;
  }
  if (cpu_times) *cpu_times = cpu;
  // Frame 0 builds every method's structures once: the times are those of the frames after it.
  if (ms.size() > 1) {
    ms.erase(ms.begin());
    cpu.erase(cpu.begin());
  }
  r.mean_ms = mean(ms);
  r.p99_ms = p99(ms);
  r.cpu_mean_ms = mean(cpu);
  r.cpu_p99_ms = p99(cpu);
  if (budget_ms > 0) {
    std::vector<double> over, wall_over;
    for (std::size_t i = 0; i < cpu.size(); ++i) {
      const double b = budgets.empty() ? budget_ms : budgets[i + (budgets.size() - cpu.size())];
      over.push_back(cpu[i] / b);
      wall_over.push_back(ms[i] / b);
    }
    r.cpu_p99_over = p99(over);
    r.cpu_p90_over = percentile(over, 0.90);
    r.p99_over = p99(wall_over);
  }
  return r;
}

/// The 1-, 5- and 15-minute load averages (Linux), or "unknown".
std::string load_average() {
  std::ifstream in("/proc/loadavg");
  double a = 0, b = 0, c = 0;
  if (!(in >> a >> b >> c)) return "unknown";
  char text[64];
  std::snprintf(text, sizeof text, "%.2f, %.2f, %.2f", a, b, c);
  return text;
}

std::string fmt(double v, const char* f = "%.4f") {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

}  // namespace
}  // namespace crumple

int main(int argc, char** argv) {
  using namespace crumple;
  bool quick = false, lean = false, per_frame = false, why = false;
  std::string clock = "wall";  // what the budgets count: wall-clock time, or processor time
  std::string only;            // --only P: the budgeted families whose spec starts with P, no free rows
  std::string out_dir = ".";
  std::vector<std::string> names = {"folding-24",   "hanging-cloth", "strip",       "cloth-on-sphere-64",
                                    "crumple-64",   "folding-100",   "folding-300"};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--quick") {
      quick = true;
      names = {"folding-24", "hanging-cloth"};
    } else if (a == "--clock" && i + 1 < argc) {
      clock = argv[++i];
      if (clock != "wall" && clock != "cpu") {
        std::cerr << "--clock must be wall or cpu\n";
        return 2;
      }
    } else if (a == "--only" && i + 1 < argc) {
      only = argv[++i];
    } else if (a == "--per-frame") {
      per_frame = true;
    } else if (a == "--why") {
      why = true;
    } else if (a == "--lean") {
      lean = true;
    } else if (a == "--out" && i + 1 < argc) {
      out_dir = argv[++i];
    } else if (a == "--scenes" && i + 1 < argc) {
      names.clear();
      std::stringstream list(argv[++i]);
      for (std::string n; std::getline(list, n, ',');) names.push_back(n);
    } else {
      std::cerr << "usage: hybrid_bench [--quick] [--lean] [--clock wall|cpu] [--only SPEC_PREFIX] [--per-frame] [--why] [--out DIR] [--scenes a,b,...]\n";
      return 2;
    }
  }
  std::filesystem::create_directories(out_dir);
  const std::vector<double> fractions =
      lean ? std::vector<double>{0.25, 0.5, 1, 2, 8} : std::vector<double>{0.25, 0.5, 1, 2, 8, 32};
  struct Family {
    const char* label;
    const char* spec;  ///< ",budget=B" is appended
    bool lean = true;  ///< also run with --lean
  };
  std::vector<Family> budgeted = {
      {"kdop cut off at the budget (cut-off exact)", "kdop"},
      {"kdop cut off, tracking the last frame's contacts", "kdop:track=on"},
      {"hybrid (stochastic zones)", "hybrid"},
      {"hybrid, exact zones (cut off)", "hybrid:search=exact", false},
      {"hybrid, exact zones of 16 faces (cut off)", "hybrid:search=exact,leaf=16"},
      {"stochastic direct, 1000 pairs + propagation", "stochastic:variant=direct,active=1000,propagation=linear"},
  };
  std::vector<Family> free = {
      {"hybrid, thesis rule: no propagation above 50% (no budget)", "hybrid:propagation=auto", false},
      {"hybrid (no budget)", "hybrid"},
      {"hybrid, exact zones (no budget)", "hybrid:search=exact", false},
      {"hybrid, exact zones of 16 faces (no budget)", "hybrid:search=exact,leaf=16"},
      {"hybrid, every=4 (no budget)", "hybrid:every=4", false},
      {"stochastic vertex, setting 1 (no budget)", "stochastic:variant=vertex,setting=1"},
  };
  if (lean) {
    std::erase_if(budgeted, [](const Family& f) { return !f.lean; });
    std::erase_if(free, [](const Family& f) { return !f.lean; });
  }
  if (!only.empty()) {
    // A comma-separated list of spec prefixes; an item ending in '$' is a whole spec.
    std::vector<std::string> items;
    std::stringstream list(only);
    for (std::string item; std::getline(list, item, ',');) items.push_back(item);
    std::erase_if(budgeted, [&](const Family& f) {
      const std::string spec = f.spec;
      return std::none_of(items.begin(), items.end(), [&](const std::string& item) {
        return item.ends_with('$') ? spec == item.substr(0, item.size() - 1) : spec.starts_with(item);
      });
    });
    free.clear();
  }
  std::ostringstream md, csv;
  csv << "scene,method,spec,budget_fraction,budget_ms,kdop_ms,recall,close_recall,worst_frame,mean_ms,p99_ms,"
         "p99_over_budget,cpu_mean_ms,cpu_p99_ms,false_contacts,frames_due_zone_left\n";
  md << "# Hybrid detector: recall against a time budget\n\n"
     << "Generated by `build/release/bench/hybrid_bench" << (quick ? " --quick" : "") << (lean ? " --lean" : "")
     << (clock == "cpu" ? " --clock cpu" : "") << (per_frame ? " --per-frame" : "") << " --out DIR`"
     << " (one thread per detector; the budget is a multiple of kdop's mean time per frame on the same scene,"
     << " measured in the same run, in processor time; the budgets count " << (clock == "cpu" ? "the thread's processor time (`clock=cpu`)" : "wall-clock time") << "; \"cpu\" columns are"
     << " the thread's processor time, without the time spent descheduled; times are of the frames after the first,"
     << " which builds every method's structures). Load average when the run started: "
     << load_average()
     << " (on a loaded machine every time includes time spent descheduled: compare methods within a table, and"
     << " read p99 as the machine's, not the method's). Method and reading: docs/hybrid.md.\n\n";
  for (const std::string& name : names) {
    std::cerr << "scene " << name << "...\n";
    const Scene s = make_scene(name, quick);
    // The reference: kdop, one thread, run twice (the second run is timed, warm).
    auto kdop_ref = make_detector(MethodSpec::parse("kdop"), {.thickness = s.h, .threads = 1});
    std::vector<ContactSet> ref;
    {
      kdop_ref->set_topology(s.frames->mesh().topology_ptr());
      Positions previous;
      for (std::size_t i = 0; i < s.frames->size(); ++i) {
        const Positions x = s.frames->positions(i);
        ContactSet c;
        kdop_ref->update(previous.empty() ? PositionsView{} : PositionsView(previous), x, c);
        ref.push_back(std::move(c));
        previous = x;
      }
    }
    // The budgets' unit: kdop's processor time per frame, the lesser of two runs frame by
    // frame (the scheduler only adds), averaged over the frames after the first (whose tree
    // build is not a frame's cost).
    const std::string load_before = load_average();
    std::vector<double> kdop_cpu, again_cpu;
    Run kd = run(s, "kdop", ref, &kdop_cpu);
    run(s, "kdop", {}, &again_cpu);
    kd.label = "kdop (exact, reference)";
    double T = 0;
    const std::size_t from = kdop_cpu.size() > 1 ? 1 : 0;
    for (std::size_t i = from; i < kdop_cpu.size(); ++i) T += std::min(kdop_cpu[i], again_cpu[i]);
    T /= static_cast<double>(kdop_cpu.size() - from);
    std::size_t contacts = 0;
    for (const auto& c : ref) contacts += c.size();
    std::vector<Run> rows = {kd};
    for (const Family& f : free) {
      std::cerr << "  " << f.spec << "\n";
      Run r = run(s, f.spec, ref);
      r.label = f.label;
      rows.push_back(r);
    }
    std::vector<bench::PlotSeries> series(budgeted.size());
    for (std::size_t k = 0; k < budgeted.size(); ++k) series[k].label = budgeted[k].label;
    for (const double fr : fractions) {
      for (std::size_t k = 0; k < budgeted.size(); ++k) {
        const double B = fr * T;
        std::string spec = budgeted[k].spec;
        spec += (spec.find(':') == std::string::npos ? ":budget=" : ",budget=") + json_number(B);
        if (clock == "cpu") spec += ",clock=cpu";
        std::cerr << "  " << spec << "\n";
        // Per frame: frame i's budget is the fraction of kdop's processor time on frame i (the
        // lesser of its two runs); the spec's budget is then only the first frame's.
        std::vector<double> budgets;
        if (per_frame) {
          for (std::size_t i = 0; i < kdop_cpu.size(); ++i) budgets.push_back(fr * std::min(kdop_cpu[i], again_cpu[i]));
        }
        Overruns over;
        Run r = run(s, spec, ref, nullptr, budgets, why ? &over : nullptr, B);
        if (why && over.frames > 0) {
          std::cerr << "    over 1.1x budget: " << over.frames << " frames, cpu " << fmt(over.cpu_ms / double(over.frames), "%.3f")
                    << " ms for a budget of " << fmt(over.budget_ms / double(over.frames), "%.3f") << " ms; wall-clock stages:";
          for (const auto& [key, value] : over.ms.items()) std::cerr << " " << key << " " << fmt(value / double(over.frames), "%.3f");
          std::cerr << "\n";
        }
        r.label = budgeted[k].label;
        r.fraction = fr;
        r.budget_ms = B;
        rows.push_back(r);
        series[k].points.emplace_back(fr, r.total.recall());
      }
    }
    const Run kd_after = run(s, "kdop", {});
    std::ostringstream section;
    section << "## " << s.name << "\n\n" << s.description << "; h = " << fmt(s.h, "%.4g") << "; " << s.frames->size()
       << " frames, " << contacts << " reference contacts (" << fmt(double(contacts) / double(s.frames->size()), "%.0f")
       << " a frame); kdop " << fmt(T, "%.3f") << " ms of processor time a frame (the budgets' unit; wall-clock mean "
       << fmt(kd.mean_ms, "%.3f") << " ms, load average " << load_before << "); run again after the budgeted runs: "
       << fmt(kd_after.cpu_mean_ms, "%.3f") << " ms processor, " << fmt(kd_after.mean_ms, "%.3f")
       << " ms wall-clock (load average " << load_average() << ").\n\n"
       << "| method | " << (per_frame ? "budget (× kdop's frame)" : "budget (× kdop)") << " | recall | recall d < h/4 | worst frame | mean ms | p99 ms | p99 / budget | "
          "cpu p99 ms | cpu p99 / budget | cpu p90 / budget | false |\n"
       << "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (const Run& r : rows) {
      const double close = r.close == 0 ? 1.0 : double(r.close_found) / double(r.close);
      section << "| " << r.label << " | " << (r.fraction > 0 ? fmt(r.fraction, "%.2f") : "–") << " | "
         << fmt(r.total.recall()) << " | " << fmt(close) << " | " << fmt(r.worst, "%.3f") << " | "
         << fmt(r.mean_ms, "%.3f") << " | " << fmt(r.p99_ms, "%.3f") << " | "
         << (r.fraction > 0 ? fmt(r.p99_over, "%.2f") : "–") << " | " << fmt(r.cpu_p99_ms, "%.3f")
         << " | " << (r.fraction > 0 ? fmt(r.cpu_p99_over, "%.2f") : "–") << " | "
         << (r.fraction > 0 ? fmt(r.cpu_p90_over, "%.2f") : "–") << " | "
         << r.total.false_contacts << " |\n";
      csv << s.name << ",\"" << r.label << "\",\"" << r.spec << "\"," << r.fraction << "," << r.budget_ms << "," << T
          << "," << r.total.recall() << "," << close << "," << r.worst << "," << r.mean_ms << "," << r.p99_ms << ","
          << (r.fraction > 0 ? r.p99_over : 0) << "," << r.cpu_mean_ms << "," << r.cpu_p99_ms << ","
          << r.total.false_contacts << "," << r.zones_left
          << "\n";
    }
    section << "\n![" << s.name << "](hybrid-" << (per_frame ? "per-frame-" : "") << s.name << ".svg)\n\n";
    std::ofstream(out_dir + "/hybrid-" + (per_frame ? "per-frame-" : "") + s.name + ".svg")
        << bench::render_svg({.title = "Recall against time budget: " + s.name,
                              .x_label = per_frame ? "budget per frame (x kdop's processor time on that frame)"
                                                  : "budget per frame (x kdop's mean processor time)",
                              .y_label = "recall",
                              .log_x = true,
                              .x_categories = {}},
                             series);
    std::cout << section.str() << std::flush;
    md << section.str();
  }
  std::ofstream(out_dir + (per_frame ? "/hybrid-per-frame.md" : "/hybrid.md")) << md.str();
  std::ofstream(out_dir + (per_frame ? "/hybrid-per-frame.csv" : "/hybrid.csv")) << csv.str();
  return 0;
}
