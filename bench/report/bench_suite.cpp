// Measurement primitives of `crumple bench` (see bench_suite.hpp).
#include "bench_suite.hpp"

#include <crumple/core/error.hpp>
#include <crumple/core/timing.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <thread>

namespace crumple::bench {

std::vector<FeedStep> feed_steps(const TimingPlan& plan) {
  std::vector<FeedStep> steps;
  for (std::size_t i = plan.first; i < plan.last; ++i) {
    steps.push_back({.frame = i, .previous = i == plan.first ? i : i - 1, .timed = i >= plan.timed_from});
  }
  return steps;
}

TimingPlan lattice_scaling_plan(std::size_t timed, int repetitions) {
  return {.first = 6, .timed_from = 8, .last = 8 + timed, .repetitions = repetitions};
}

TimingPlan frame_pair_plan(int repetitions) {
  return {.first = 0, .timed_from = 1, .last = 2, .repetitions = repetitions};
}

std::vector<Timing> time_methods_against_first(std::shared_ptr<const Topology> topology,
                                               const std::vector<Positions>& frames,
                                               const std::vector<std::string>& specs, const DetectorOptions& options,
                                               const TimingPlan& plan,
                                               const std::function<void(int, std::size_t)>& on_run) {
  CRUMPLE_CHECK(plan.first <= plan.timed_from && plan.timed_from <= plan.last && plan.last <= frames.size(),
                "timing plan out of the frame range");
  CRUMPLE_CHECK(plan.repetitions >= 1, "at least one repetition");
  CRUMPLE_CHECK(!specs.empty(), "at least one method");
  const std::size_t timed = plan.last - plan.timed_from;
  const std::vector<FeedStep> steps = feed_steps(plan);
  std::vector<MethodSpec> methods;
  for (const std::string& spec : specs) methods.push_back(MethodSpec::parse(spec));

  const std::size_t n = methods.size();
  std::vector<Timing> t(n);
  for (std::size_t m = 0; m < n; ++m) t[m].spec = methods[m].to_string();
  std::vector<std::vector<std::vector<double>>> samples(n, std::vector<std::vector<double>>(timed));
  std::vector<ContactSet> reference;  // method 0's contacts per timed frame (first repetition)
  ContactSet out;
  for (int rep = 0; rep < plan.repetitions; ++rep) {
    for (std::size_t m = 0; m < n; ++m) {
      if (on_run) on_run(rep, m);
      auto detector = make_detector(methods[m], options);
      detector->set_topology(topology);
      for (const FeedStep& step : steps) {
        const auto start = std::chrono::steady_clock::now();
        detector->update(frames[step.previous], frames[step.frame], out);
        const double ms = ms_since(start);
        if (!step.timed) continue;
        const std::size_t k = step.frame - plan.timed_from;
        samples[m][k].push_back(ms);
        if (rep > 0) continue;  // seeded: every repetition finds the same contacts
        t[m].distance_evals += detector->stats().get("distance_evals") / static_cast<double>(timed);
        if (m == 0) reference.push_back(out);
        t[m].match.push_back(match_contacts(out, reference[k]));
      }
    }
  }
  for (std::size_t m = 0; m < n; ++m) {
    t[m].ms.reserve(timed);
    for (auto& s : samples[m]) {
      std::nth_element(s.begin(), s.begin() + static_cast<std::ptrdiff_t>(s.size() / 2), s.end());
      t[m].ms.push_back(s[s.size() / 2]);
    }
  }
  return t;
}

namespace {

/// First line of a command's output, empty on failure.
std::string command_line_output(const std::string& command) {
  std::string out;
  if (FILE* p = ::popen(command.c_str(), "r")) {
    std::array<char, 256> buf{};
    if (std::fgets(buf.data(), static_cast<int>(buf.size()), p) != nullptr) out = buf.data();
    ::pclose(p);
  }
  while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
  return out;
}

}  // namespace

std::string machine_description() {
  std::string model = "unknown CPU";
  std::ifstream cpuinfo("/proc/cpuinfo");
  for (std::string line; std::getline(cpuinfo, line);) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) model = line.substr(line.find_first_not_of(' ', colon + 1));
      break;
    }
  }
  std::string out = model;
  out.append(", ").append(std::to_string(std::thread::hardware_concurrency())).append(" hardware threads, ");
#if defined(__clang__)
  out.append("clang ").append(__clang_version__);
#elif defined(__GNUC__)
  out.append("g++ ").append(std::to_string(__GNUC__)).append(".").append(std::to_string(__GNUC_MINOR__));
#endif
#if defined(NDEBUG)
  out.append(", optimised build");
#else
  out.append(", unoptimised build (assertions on)");
#endif
  return out;
}

std::string source_commit() {
#ifdef CRUMPLE_SOURCE_DIR
  const std::string dir = CRUMPLE_SOURCE_DIR;
  const std::string head = command_line_output("git -C '" + dir + "' rev-parse --short=12 HEAD 2>/dev/null");
  if (head.empty()) return "unknown";
  const std::string dirty =
      command_line_output("git -C '" + dir + "' status --porcelain --untracked-files=no 2>/dev/null");
  return dirty.empty() ? head : head + "-dirty";
#else
  return "unknown";
#endif
}

std::string utc_now() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  ::gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

}  // namespace crumple::bench
