#include <crumple/core/error.hpp>
#include <crumple/core/spec_text.hpp>
#include <crumple/detect/method.hpp>

#include <algorithm>
#include <array>
#include <cstdlib>

namespace crumple {

namespace {

constexpr std::array<ParamInfo, 1> kNaiveParams{{
    {"cull", "on",
     "on | off: skip the pairs whose bounding boxes, padded beyond any rounding of the distance, "
     "are apart (the same contacts); off = the thesis' loop, every pair through the exact test"},
}};

constexpr std::array<ParamInfo, 11> kStochasticParams{{
    {"variant", "direct",
     "simple | propagate-by-convergence | direct | vertex (thesis 3.2.2.5; docs/stochastic.md)"},
    {"active", "100", "maximum near pairs kept per pair type (setting=1: 10)"},
    {"draw", "0", "maximum random pairs drawn per frame and pair type (0 = active)"},
    {"propagation", "auto",
     "none | linear | full | auto (full for simple, linear otherwise; none with setting=2)"},
    {"near", "2", "near distance as a multiple of the thickness (>= 1): farther pairs are dropped"},
    {"steps", "16", "convergence moves per walk and frame; an unfinished walk goes on next frame"},
    {"ef", "off", "also track edge-face pairs (on by itself when tt contacts are asked)"},
    {"seed", "1", "random seed (same seed and frames: same contacts)"},
    {"budget", "0",
     "time budget per frame in ms (0 = none): kept pairs first, then draws and propagation "
     "until it is spent (results then depend on the machine's speed)"},
    {"clock", "wall",
     "wall | cpu: the clock the budget counts on; cpu = this thread's processor time (for "
     "measuring budgets on a shared machine; one thread)"},
    {"setting", "0",
     "thesis settings: 1 = 10 active pairs with propagation, 2 = 100 without (keys override)"},
}};

constexpr std::array<ParamInfo, 13> kKdopParams{{
    {"k", "18", "6 | 14 | 18 | 26: k-DOP directions"},
    {"arity", "4", "2 | 4 | 8: children per node"},
    {"leaf", "48", "maximum faces per leaf (1..64)"},
    {"rebuild", "2", "rebuild the tree when the refit quality metric grows past this factor"},
    {"sweep", "off",
     "on | off: the hierarchy also covers the motion from the previous frame (the thesis' "
     "motion-oriented inflation; same contacts, which are proximity at the current positions, "
     "so off is faster)"},
    {"cones", "off",
     "on | off: skip the self-test of patches that provably cannot intersect themselves "
     "(normals in a cone, star-shaped contour); intersection-only queries (--kinds tt)"},
    {"coherence", "on",
     "on | off: patches whose vertices all moved by nearly the same vector since a refresh "
     "frame reuse that frame's candidates instead of being traversed again; proximity "
     "queries (same contacts)"},
    {"max_contacts", "0", "cap on the contacts of one frame (0 = none); see overflow"},
    {"overflow", "error",
     "error | truncate: over max_contacts, throw, or keep the first contacts in canonical "
     "order (stats: overflow, contacts_dropped)"},
    {"budget", "0",
     "time budget per frame in ms (0 = none), from the start of the call: the traversal and "
     "narrow phase stop early enough for the gather (its cost on the last frame) and the frame "
     "returns the contacts found so far (a subset; results then depend on the machine's speed)"},
    {"pairs", "0",
     "most candidate face pairs narrow-tested per frame (0 = all): a budget counted in work, "
     "in the traversal's order (stats: cut, pairs_tested)"},
    {"track", "off",
     "on | off: with a budget, first test the last frame's contacts again, and begin the "
     "traversal where the last frame's stopped (frames cut short cover the mesh in turn)"},    {"clock", "wall",
     "wall | cpu: the clock the budget counts on; cpu = this thread's processor time (for "
     "measuring budgets on a shared machine; one thread)"},
}};
constexpr std::array<ParamInfo, 4> kHashParams{{
    {"cell", "0", "cell size as a multiple of the mean edge length (0 = max(mean edge, 2h))"},
    {"table", "0", "number of hash buckets (0 = smallest prime >= 2x the cell entries)"},
    {"max_contacts", "0", "cap on the contacts of one frame (0 = none); see overflow"},
    {"overflow", "error",
     "error | truncate: over max_contacts, throw, or keep the first contacts in canonical "
     "order (stats: overflow, contacts_dropped)"},
}};
constexpr std::array<ParamInfo, 3> kSapParams{{
    {"axis", "auto", "auto | x | y | z: sweep axis (auto = largest spread of the face boxes)"},
    {"max_contacts", "0", "cap on the contacts of one frame (0 = none); see overflow"},
    {"overflow", "error",
     "error | truncate: over max_contacts, throw, or keep the first contacts in canonical "
     "order (stats: overflow, contacts_dropped)"},
}};

constexpr std::array<ParamInfo, 11> kHybridParams{{
    {"leaf", "64", "faces per leaf of the coarse hierarchy (4..4096); zones are overlapping leaf pairs"},
    {"every", "1", "coverage period: a zone not examined for this many frames is examined first"},
    {"budget", "0",
     "time budget per frame in ms (0 = none), from the start of the call: zones are examined in "
     "order until what is left only covers the work after the search (its cost on the last "
     "frame), the rest come first next frame (results then depend on the machine's speed)"},
    {"clock", "wall",
     "wall | cpu: the clock the budget counts on; cpu = this thread's processor time (for "
     "measuring budgets on a shared machine; one thread)"},
    {"zones", "0", "most zones examined per frame (0 = all): a budget counted in zones"},
    {"search", "stochastic",
     "stochastic | exact: inside a zone, random pairs converged (the thesis) or every pair"},
    {"draw", "0", "random pairs per zone and pair type (0 = the thesis' rule from the zone's size and contacts)"},
    {"propagation", "linear",
     "none | linear | full | auto (the thesis' rule: linear, none in zones above 50% in collision)"},
    {"near", "0", "near distance as a multiple of the thickness (0 = from each leaf's motion, 2..8)"},
    {"steps", "8", "convergence moves per walk and frame; an unfinished walk goes on next frame"},
    {"seed", "1", "random seed (same seed and frames, no budget: same contacts)"},
}};

constexpr std::array<MethodInfo, 6> kMethods{{
    {Method::Naive, "naive",
     "O(n^2) test of every vertex-face and edge-edge pair (the thesis baseline and the exact "
     "reference)",
     {.exact = true, .stochastic = false, .uses_motion = false}, kNaiveParams},
    {Method::Stochastic, "stochastic",
     "random pairs converged to local minima of distance and kept across frames, with "
     "propagation (the thesis' method; cost set by its parameters, may miss contacts)",
     {.exact = false, .stochastic = true, .uses_motion = false}, kStochasticParams},
    {Method::Kdop, "kdop",
     "exact: inflated, motion-oriented k-DOP hierarchy with refit and self-traversal, feature "
     "ownership and orphan lists (docs/exact-detectors.md)",
     {.exact = true, .stochastic = false, .uses_motion = true}, kKdopParams},
    {Method::Hash, "hash",
     "exact: spatial hashing of face boxes (Teschner et al. 2003) + the shared exact narrow "
     "phase",
     {.exact = true, .stochastic = false, .uses_motion = false}, kHashParams},
    {Method::Sap, "sap",
     "exact: sweep and prune of face boxes with insertion sort across frames (I-COLLIDE) + the "
     "shared exact narrow phase",
     {.exact = true, .stochastic = false, .uses_motion = false}, kSapParams},
    {Method::Hybrid, "hybrid",
     "the thesis' future work: stochastic search inside the zones of a coarse hierarchy, every "
     "zone examined within `every` frames, under a time budget (docs/hybrid.md)",
     {.exact = false, .stochastic = true, .uses_motion = true}, kHybridParams},
}};

std::string join_names() {
  return join_list(kMethods, [](const MethodInfo& m) { return std::string(m.name); });
}

std::string join_keys(const MethodInfo& info) {
  if (info.params.empty()) return "none";
  return join_list(info.params, [](const ParamInfo& p) { return std::string(p.key); });
}

}  // namespace

std::span<const MethodInfo> all_methods() { return kMethods; }

const MethodInfo& method_info(Method method) {
  for (const auto& m : kMethods) {
    if (m.method == method) return m;
  }
  throw InputError("unknown method enum value " + std::to_string(static_cast<int>(method)));
}

std::string_view to_string(Method method) { return method_info(method).name; }

Method parse_method(std::string_view name) {
  for (const auto& m : kMethods) {
    if (m.name == name) return m.method;
  }
  throw InputError("unknown method '" + std::string(name) + "' (valid: " + join_names() + ")");
}

MethodSpec MethodSpec::parse(std::string_view text) {
  const std::string_view name = trim_blanks(trim_blanks(text).substr(0, trim_blanks(text).find(':')));
  MethodSpec spec(parse_method(name));
  const MethodInfo& info = method_info(spec.method_);
  const SpecText split = SpecText::split(
      text, "method spec", std::string("valid keys for ").append(info.name).append(": ").append(join_keys(info)));
  for (const auto& [key, value] : split.items) spec.set(key, value);
  return spec;
}

MethodSpec& MethodSpec::set(std::string key, std::string value) {
  const MethodInfo& info = method_info(method_);
  set_spec_key(params_, info.params, std::move(key), std::move(value), "method " + std::string(info.name));
  return *this;
}

std::optional<std::string> MethodSpec::get(std::string_view key) const {
  const std::string* value = find_spec_value(params_, key);
  if (!value) return std::nullopt;
  return *value;
}

void MethodSpec::bad_value(std::string_view key, const std::string& value,
                           std::string_view expected) const {
  throw InputError("method " + std::string(crumple::to_string(method_)) + ": key '" + std::string(key) +
                   "' expects " + std::string(expected) + ", got '" + value + "'");
}

long long MethodSpec::get_int(std::string_view key, long long fallback) const {
  const auto value = get(key);
  if (!value) return fallback;
  const auto out = parse_integer(*value);
  if (!out) bad_value(key, *value, "an integer");
  return *out;
}

double MethodSpec::get_double(std::string_view key, double fallback) const {
  const auto value = get(key);
  if (!value) return fallback;
  const auto out = parse_number(*value);
  if (!out) bad_value(key, *value, "a number");
  return *out;
}

bool MethodSpec::get_bool(std::string_view key, bool fallback) const {
  const auto value = get(key);
  if (!value) return fallback;
  const auto out = parse_switch(*value);
  if (!out) bad_value(key, *value, "on or off");
  return *out;
}

std::string MethodSpec::get_choice(std::string_view key, std::string_view fallback,
                                   std::span<const std::string_view> choices) const {
  const auto value = get(key);
  if (!value) return std::string(fallback);
  for (auto c : choices) {
    if (c == *value) return *value;
  }
  std::string expected = "one of";
  for (auto c : choices) expected.append(" ").append(c);
  bad_value(key, *value, expected);
}

std::string MethodSpec::to_string() const { return format_spec(crumple::to_string(method_), params_); }

}  // namespace crumple
