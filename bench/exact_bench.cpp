// Benchmark of the exact detectors (kdop, hash, sap) on the five real scenes, and generator of
// the cached naive reference contact sets used by tests/detect/exact_detectors_test.cpp.
//
// Timing (docs/benchmarks/exact.md):
//   build-exact/bench/exact_bench --json docs/benchmarks/exact.json --md docs/benchmarks/exact.md
// For each scene: the second frame with motion from the first, h = 1e-3 x the first frame's
// bounding-box diagonal, VF + EE (and, with --tt, the intersection-only query), 1 and 2
// threads. Each repetition starts the detector afresh (set_topology), runs an untimed update on
// the first frame (so persistent state — tree, sort order, orphan bounds — is that of the
// previous step), then the timed update(first, second);
// repetition r of every (method, threads) pair before repetition r + 1 of any.
// The median wall time is reported with the stats of that run (refit / traversal / narrow ms,
// candidates).
//
// References (tests/data/reference/real_meshes.txt), appended to FILE, one scene at a time:
//   B=build-exact/bench/exact_bench; R=tests/data/reference/real_meshes.txt; rm -f $R
//   $B --reference $R --scenes 'cloth-funnel;armadillo-rollers'
//   $B --reference $R --scenes 'rod-twist;cloth-ball;n-body' --small-only
// Without --small-only, `naive` runs on every frame at h = 1e-2 x diagonal (millions of
// contacts) and the 1e-3 set is derived by filtering (the kernels do not depend on h; if a
// distance lies within 1e-12 relative of the smaller h, naive is rerun at that h). With
// --small-only, naive runs at 1e-3 only (the 1e-2 sets of the big scenes hold tens of
// millions of contacts). Each line: scene, frame file, relative thickness (of the first
// frame's diagonal), VF and EE counts, and the FNV-1a 64 hash of the `write_contacts` text
// (pairs and 17-digit distances: equal hashes mean identical pairs and bit-identical
// distances). Regenerate whenever the distance kernels change. Each frame's lines are appended
// atomically; the timing tables are written atomically at the end. `--help` lists the options,
// which are all checked before any scene is loaded.
#include <crumple/core/atomic_file.hpp>
#include <crumple/core/json.hpp>
#include <crumple/detect/detector.hpp>
#include <crumple/io/mesh_io.hpp>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <time.h>
#include <unistd.h>

namespace {

/// CPU time of the whole process (all threads), in ms: robust to other load on the machine.
double cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return 1e3 * static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_nsec);
}

using namespace crumple;

struct Scene {
  const char* name;
  const char* frame0;
  const char* frame1;
};

constexpr Scene kScenes[] = {
    {"cloth-ball", "sample-scalable-ccd/cloth-ball/frames/cloth_ball92.ply",
     "sample-scalable-ccd/cloth-ball/frames/cloth_ball93.ply"},
    {"cloth-funnel", "sample-scalable-ccd/cloth-funnel/frames/227.ply",
     "sample-scalable-ccd/cloth-funnel/frames/228.ply"},
    {"rod-twist", "sample-scalable-ccd/rod-twist/frames/3036.ply",
     "sample-scalable-ccd/rod-twist/frames/3037.ply"},
    {"armadillo-rollers", "sample-scalable-ccd/armadillo-rollers/frames/326.ply",
     "sample-scalable-ccd/armadillo-rollers/frames/327.ply"},
    {"n-body", "sample-scalable-ccd/n-body-simulation/frames/balls16_18.ply",
     "sample-scalable-ccd/n-body-simulation/frames/balls16_19.ply"},
};

std::uint64_t fnv1a(const std::string& text) {
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : text) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

std::string contacts_text(const ContactSet& set) {
  std::ostringstream out;
  write_contacts(out, set);
  return out.str();
}

std::string base_name(const std::string& path) { return path.substr(path.find_last_of('/') + 1); }

ContactSet run_once(const std::string& spec, const TriMesh& mesh, PositionsView previous, PositionsView x,
                    Scalar h, int threads, ContactKinds kinds = {}) {
  auto d = make_detector(MethodSpec::parse(spec), {.thickness = h, .kinds = kinds, .threads = threads});
  d->set_topology(mesh.topology_ptr());
  ContactSet out;
  d->update(previous, x, out);
  return out;
}

/// One line of the reference file: scene, frame file, relative thickness, counts and hash.
std::string reference_line(const char* scene, const std::string& file, const char* rel, const ContactSet& set) {
  char hash[32];
  std::snprintf(hash, sizeof hash, "%016llx", static_cast<unsigned long long>(fnv1a(contacts_text(set))));
  return std::string(scene) + " " + base_name(file) + " " + rel + " " + std::to_string(set.vf.size()) + " " +
         std::to_string(set.ee.size()) + " " + hash + "\n";
}

/// Scene s is to be run: `only` (the --scenes list) is empty or names it.
bool wanted(const std::vector<std::string>& only, const Scene& s) {
  return only.empty() || std::find(only.begin(), only.end(), s.name) != only.end();
}

int reference(const std::string& data, const std::string& out_path, int threads,
              const std::vector<std::string>& only, bool with_large) {
  // Each frame's lines are appended atomically (the file rewritten whole, then renamed over the
  // old one): an interrupted run leaves the lines of the frames it finished, never half a line.
  const auto append = [&out_path](const std::string& lines) {
    std::string text;
    if (std::ifstream in(out_path); in) text.assign(std::istreambuf_iterator<char>(in), {});
    if (!text.empty() && text.back() != '\n') text += '\n';
    write_file_atomically(out_path, [&](std::ostream& o) { o << text << lines; });
  };
  for (const Scene& s : kScenes) {
    if (!wanted(only, s)) continue;
    const TriMesh m0 = io::read_mesh(data + "/" + s.frame0);
    const Scalar diag = compute_bounds(m0.positions()).diagonal();
    for (const char* file : {s.frame0, s.frame1}) {
      const TriMesh m = io::read_mesh(data + "/" + file);
      const auto start = std::chrono::steady_clock::now();
      const Scalar h = 1e-3 * diag;
      if (!with_large) {  // the smaller thickness only, directly
        append(reference_line(s.name, file, "0.001", run_once("naive", m0, {}, m.positions(), h, threads)));
        std::cerr << s.name << " " << base_name(file) << " done\n";
        continue;
      }
      const ContactSet big = run_once("naive", m0, {}, m.positions(), 1e-2 * diag, threads);
      ContactSet small;
      bool ambiguous = false;
      for (const auto& c : big.vf) {
        ambiguous |= std::abs(c.distance - h) <= 1e-12 * h;
        if (c.distance < h) small.vf.push_back(c);
      }
      for (const auto& c : big.ee) {
        ambiguous |= std::abs(c.distance - h) <= 1e-12 * h;
        if (c.distance < h) small.ee.push_back(c);
      }
      if (ambiguous) small = run_once("naive", m0, {}, m.positions(), h, threads);
      const double s_taken =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      append(reference_line(s.name, file, "0.001", small) + reference_line(s.name, file, "0.01", big));
      std::cerr << s.name << " " << base_name(file) << ": " << s_taken << " s\n";
    }
  }
  return 0;
}

struct Row {
  std::string scene, method, query;
  int threads = 0;
  double ms = 0, cpu_ms = 0, refit_ms = 0, traversal_ms = 0, narrow_ms = 0, sort_ms = 0, candidates = 0;
  std::size_t vf = 0, ee = 0, tt = 0;
};

int bench(const std::string& data, const std::vector<std::string>& methods, const std::vector<int>& thread_counts, int repeat, bool tt,
          const std::string& json_path, const std::string& md_path, const std::vector<std::string>& only) {
  std::vector<Row> rows;
  // Progress on stderr: a line per scene, and on a terminal the repetition being run.
  const bool terminal = ::isatty(2) != 0;
  const auto scene_count = static_cast<std::size_t>(
      std::count_if(std::begin(kScenes), std::end(kScenes), [&only](const Scene& s) { return wanted(only, s); }));
  std::size_t scene_number = 0;
  for (const Scene& s : kScenes) {
    if (!wanted(only, s)) continue;
    std::fprintf(stderr, "[%zu/%zu] %s\n", ++scene_number, scene_count, s.name);
    const TriMesh m0 = io::read_mesh(data + "/" + s.frame0);
    const Positions x1 = io::read_mesh(data + "/" + s.frame1).positions();
    const Positions& x0 = m0.positions();
    const Scalar h = 1e-3 * compute_bounds(x0).diagonal();
    std::vector<std::pair<std::string, ContactKinds>> queries{{"vf,ee", ContactKinds::parse("vf,ee")}};
    if (tt) queries.push_back({"tt", ContactKinds::parse("tt")});
    for (const auto& [qname, kinds] : queries) {
      // Every (method, threads) detector runs repetition r before any runs r + 1: this VM's
      // speed drifts by 10-40% over minutes, and one method's repetitions back to back could
      // land in another phase than the next method's. Each timed update follows an untimed one
      // on the first frame, so caches are warm whatever ran before.
      struct Combo {
        std::string method;
        int threads = 0;
        std::unique_ptr<Detector> detector;
        ContactSet out;
        std::vector<std::pair<double, Row>> runs;
      };
      std::vector<Combo> combos;
      for (const std::string& method : methods) {
        for (int threads : thread_counts) {
          Combo c{method, threads,
                  make_detector(MethodSpec::parse(method), {.thickness = h, .kinds = kinds, .threads = threads}),
                  {}, {}};
          c.detector->set_topology(m0.topology_ptr());
          combos.push_back(std::move(c));
        }
      }
      for (int r = 0; r < repeat; ++r) {
        if (terminal) std::fprintf(stderr, "\r  %s: repetition %d/%d", qname.c_str(), r + 1, repeat);
        for (Combo& c : combos) {
          Detector& d = *c.detector;
          // From scratch each repetition (tree, orphan bounds): the timed frame then always
          // follows the same history, one step (the untimed one) after a fresh start.
          d.set_topology(m0.topology_ptr());
          d.update(x0, c.out);
          const double cpu_start = cpu_ms();
          const auto start = std::chrono::steady_clock::now();
          d.update(x0, x1, c.out);
          Row row;
          row.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
          row.cpu_ms = cpu_ms() - cpu_start;
          row.scene = s.name;
          row.method = c.method;
          row.query = qname;
          row.threads = c.threads;
          row.refit_ms = d.stats().get("refit_ms");
          row.traversal_ms = d.stats().get("traversal_ms");
          row.narrow_ms = d.stats().get("narrow_ms");
          row.sort_ms = d.stats().get("sort_ms");
          row.candidates = d.stats().get("candidates");
          row.vf = c.out.vf.size();
          row.ee = c.out.ee.size();
          row.tt = c.out.tt.size();
          c.runs.emplace_back(row.ms, row);
        }
      }
      if (terminal) std::fprintf(stderr, "\r\033[K");
      for (Combo& c : combos) {
        std::sort(c.runs.begin(), c.runs.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
        const Row& med = c.runs[c.runs.size() / 2].second;
        std::fprintf(stderr, "%-18s %-6s %-24s %d thr  %9.2f ms  cpu %9.2f ms  (refit %.2f, traversal %.2f, narrow %.2f, sort %.2f; %.0f candidates; vf %zu ee %zu tt %zu)\n",
                     s.name, qname.c_str(), c.method.c_str(), c.threads, med.ms, med.cpu_ms, med.refit_ms,
                     med.traversal_ms, med.narrow_ms, med.sort_ms, med.candidates, med.vf, med.ee, med.tt);
        rows.push_back(med);
      }
    }
  }
  if (!json_path.empty()) write_file_atomically(json_path, [&](std::ostream& out) {
    out << "[\n";
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const Row& r = rows[i];
      out << "  "
          << JsonObject()
                 .add("scene", r.scene)
                 .add("query", r.query)
                 .add("method", r.method)
                 .add("threads", r.threads)
                 .add("ms", r.ms)
                 .add("cpu_ms", r.cpu_ms)
                 .add("refit_ms", r.refit_ms)
                 .add("traversal_ms", r.traversal_ms)
                 .add("narrow_ms", r.narrow_ms)
                 .add("sort_ms", r.sort_ms)
                 .add("candidates", r.candidates)
                 .add("vf", r.vf)
                 .add("ee", r.ee)
                 .add("tt", r.tt)
                 .str()
          << (i + 1 < rows.size() ? ",\n" : "\n");
    }
    out << "]\n";
  });
  if (!md_path.empty()) write_file_atomically(md_path, [&](std::ostream& out) {
    out << "| scene | query | method | threads | total ms | CPU ms | refit ms | traversal ms | narrow ms | sort ms | candidates | VF | EE | TT |\n";
    out << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for (const Row& r : rows) {
      char line[512];
      std::snprintf(line, sizeof line, "| %s | %s | `%s` | %d | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.0f | %zu | %zu | %zu |\n",
                    r.scene.c_str(), r.query.c_str(), r.method.c_str(), r.threads, r.ms, r.cpu_ms, r.refit_ms,
                    r.traversal_ms, r.narrow_ms, r.sort_ms, r.candidates, r.vf, r.ee, r.tt);
      out << line;
    }
  });
  return 0;
}

std::vector<std::string> split(const std::string& list) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (start <= list.size()) {
    const std::size_t end = std::min(list.find(';', start), list.size());
    if (end > start) out.push_back(list.substr(start, end - start));
    start = end + 1;
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  // The shared real meshes live beside the checkout (../shared/data), as for the tests.
  std::string data =
      (std::filesystem::path(__FILE__).parent_path() / ".." / ".." / "shared" / "data").lexically_normal().string();
  std::string ref, json, md;
  std::string methods = "kdop;hash;sap";
  std::string scenes;
  int repeat = 5, threads = 0;
  bool tt = false, small_only = false;
  std::vector<int> thread_counts{1, 2};

  std::string scene_names;
  for (const Scene& s : kScenes) scene_names += (scene_names.empty() ? "" : ", ") + std::string(s.name);
  CLI::App app{
      "Times the exact detectors on the real scenes: for each scene, the second frame with motion from the\n"
      "first, h = 1e-3 x the first frame's bounding-box diagonal, every method and thread count; prints\n"
      "the median run's phases and writes the table as JSON and markdown (docs/benchmarks/exact.md).\n"
      "With --reference, instead writes the cached naive contact sets the tests compare against.",
      "exact_bench"};
  // Checked before any work, so that a typo does not cost a whole run.
  const auto each = [](std::string what, auto check) {
    return CLI::Validator(
        [check, what](std::string& list) -> std::string {
          const std::vector<std::string> items = split(list);
          if (items.empty()) return what + " list is empty";
          for (const std::string& item : items) {
            if (std::string error = check(item); !error.empty()) return error;
          }
          return {};
        },
        "LIST");
  };
  const auto method_ok = [](const std::string& m) -> std::string {
    try {
      make_detector(MethodSpec::parse(m), {});  // the method's own keys are checked here
    } catch (const std::exception& e) {
      return e.what();
    }
    return {};
  };
  const auto scene_ok = [scene_names](const std::string& name) -> std::string {
    for (const Scene& s : kScenes) {
      if (name == s.name) return {};
    }
    return "unknown scene '" + name + "' (scenes: " + scene_names + ")";
  };
  // An output's folder must exist: found out now rather than after the run.
  const CLI::Validator writable(
      [](std::string& path) -> std::string {
        if (path.empty()) return "the file name is empty";
        std::error_code error;
        const std::filesystem::path parent = std::filesystem::absolute(path, error).parent_path();
        if (error || !std::filesystem::is_directory(parent, error)) {
          return "folder " + parent.string() + " does not exist";
        }
        if (std::filesystem::is_directory(path, error)) return path + " is a folder";
        return {};
      },
      "FILE");
  app.add_option("--data", data, "Folder of the real meshes")->check(CLI::ExistingDirectory)->capture_default_str();
  auto* methods_opt = app.add_option("--methods", methods, "Detector specs separated by ';' (e.g. 'kdop;kdop:k=14')")
                          ->check(each("method", method_ok))
                          ->capture_default_str();
  app.add_option("--scenes", scenes, "Scenes separated by ';' (default: all: " + scene_names + ")")
      ->check(each("scene", scene_ok));
  auto* repeat_opt = app.add_option("--repeat", repeat, "Timed runs per method and thread count (median reported)")
                         ->check(CLI::Range(1, 1000))
                         ->capture_default_str();
  auto* counts_opt = app.add_option("--thread-counts", thread_counts, "Thread counts separated by ';' (0 = all cores)")
                         ->delimiter(';')
                         ->check(CLI::Range(0, 1024))
                         ->capture_default_str();
  auto* tt_opt = app.add_flag("--tt", tt, "Also time the intersection-only query (non-adjacent intersecting faces)");
  auto* json_opt = app.add_option("--json", json, "Write the table as JSON to FILE (atomically)")->check(writable);
  auto* md_opt = app.add_option("--md", md, "Write the table as markdown to FILE (atomically)")->check(writable);
  auto* ref_opt = app.add_option("--reference", ref,
                                 "Instead of timing: append each frame's naive reference line(s) to FILE (atomically)")
                      ->check(writable);
  app.add_option("--threads", threads, "Threads of the reference runs (0 = all cores)")
      ->check(CLI::Range(0, 1024))
      ->needs(ref_opt);
  app.add_flag("--small-only", small_only, "Reference at h = 1e-3 x diagonal only (not also 1e-2)")->needs(ref_opt);
  for (auto* timing : {methods_opt, repeat_opt, counts_opt, tt_opt, json_opt, md_opt}) ref_opt->excludes(timing);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    if (!ref.empty()) return reference(data, ref, threads, split(scenes), !small_only);
    return bench(data, split(methods), thread_counts, repeat, tt, json, md, split(scenes));
  } catch (const std::exception& e) {
    std::cerr << "exact_bench: error: " << e.what() << "\n";
    return 1;
  }
}
