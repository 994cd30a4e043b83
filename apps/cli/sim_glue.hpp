#pragma once
// Glue between the file formats (crumple::io, pugixml) and the simulator (crumple::sim), kept in
// the app so the library does not depend on io: MassSpringData <-> Model/State, and the small
// JSON side file that lets `crumple simulate DIR/state.x3d` resume a run bit for bit.

#include <crumple/core/atomic_file.hpp>
#include <crumple/core/error.hpp>
#include <crumple/core/json.hpp>
#include <crumple/io/x3d.hpp>
#include <crumple/sim/mass_spring.hpp>
#include <crumple/sim/scene.hpp>

#include <charconv>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace crumple::cli {

/// A scene spec with the `--param KEY=VALUE` options applied (keys checked by the scene).
inline sim::SceneSpec apply_params(sim::SceneSpec spec, const std::vector<std::string>& params) {
  for (const std::string& item : params) {
    const auto eq = item.find('=');
    if (eq == std::string::npos) throw InputError("--param expects KEY=VALUE, got '" + item + "'");
    spec.set(item.substr(0, eq), item.substr(eq + 1));
  }
  return spec;
}

/// Whether a file's bytes contain `needle` (e.g. an X3D file holding a `MassSpring` node).
inline bool file_mentions(const std::filesystem::path& path, const std::string& needle) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str().find(needle) != std::string::npos;
}

inline sim::Model model_from_mass_spring(const io::MassSpringData& d) {
  std::vector<sim::Spring> springs;
  springs.reserve(d.springs.size());
  for (std::size_t s = 0; s < d.springs.size(); ++s) {
    springs.push_back({d.springs[s][0], d.springs[s][1], d.stiffness[s], d.damping_ratio[s], d.rest_length[s]});
  }
  return sim::Model::create(d.masses, std::move(springs), d.faces);
}

inline sim::State state_from_mass_spring(const io::MassSpringData& d, Scalar time) {
  return sim::State{d.positions, d.velocities, time};
}

inline io::MassSpringData to_mass_spring(const sim::Model& model, const sim::State& state) {
  io::MassSpringData d;
  d.positions = state.x;
  d.velocities = state.v;
  d.masses.assign(model.mass().begin(), model.mass().end());
  for (const sim::Spring& s : model.springs()) {
    d.springs.push_back({s.a, s.b});
    d.stiffness.push_back(s.stiffness);
    d.damping_ratio.push_back(s.damping_ratio);
    d.rest_length.push_back(s.rest_length);
  }
  d.faces.assign(model.topology().faces().begin(), model.topology().faces().end());
  return d;
}

/// The side file of a saved state: flat JSON object of strings, numbers and booleans, kept as
/// text values (numbers are read back exactly: they are written as the shortest round-trip text).
struct SideFile {
  std::map<std::string, std::string> values;

  bool has(const std::string& key) const { return values.count(key) > 0; }
  const std::string& text(const std::string& key, const std::filesystem::path& path) const {
    auto it = values.find(key);
    if (it == values.end()) throw ParseError(path.string(), {}, "missing key '" + key + "'");
    return it->second;
  }
  double number(const std::string& key, const std::filesystem::path& path) const {
    const std::string& t = text(key, path);
    double v = 0;
    const auto [ptr, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    if (ec != std::errc() || ptr != t.data() + t.size()) {
      throw ParseError(path.string(), {}, "key '" + key + "' expects a number, got '" + t + "'");
    }
    return v;
  }
};

/// Parses a flat JSON object (no nesting, no arrays); throws ParseError naming the file.
inline SideFile read_side_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ParseError(path.string(), {}, "cannot open");
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string s = buffer.str();
  std::size_t i = 0;
  const auto fail = [&](const std::string& what) -> void {
    throw ParseError(path.string(), {}, "byte " + std::to_string(i) + ": expected " + what);
  };
  const auto skip = [&] {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\n' || s[i] == '\r' || s[i] == '\t')) ++i;
  };
  const auto string_token = [&]() {
    if (i >= s.size() || s[i] != '"') fail("a string");
    std::string out;
    for (++i; i < s.size() && s[i] != '"'; ++i) {
      if (s[i] == '\\') {
        if (++i >= s.size()) fail("an escape");
        const char c = s[i];
        out += c == 'n' ? '\n' : c == 't' ? '\t' : c;
      } else {
        out += s[i];
      }
    }
    if (i >= s.size()) fail("a closing quote");
    ++i;
    return out;
  };
  SideFile file;
  skip();
  if (i >= s.size() || s[i] != '{') fail("'{'");
  ++i;
  skip();
  if (i < s.size() && s[i] == '}') return file;
  while (true) {
    skip();
    const std::string key = string_token();
    skip();
    if (i >= s.size() || s[i] != ':') fail("':'");
    ++i;
    skip();
    std::string value;
    if (i < s.size() && s[i] == '"') {
      value = string_token();
    } else {
      const std::size_t start = i;
      while (i < s.size() && s[i] != ',' && s[i] != '}' && s[i] != ' ' && s[i] != '\n') ++i;
      value = s.substr(start, i - start);
      if (value.empty()) fail("a value");
    }
    file.values[key] = value;
    skip();
    if (i < s.size() && s[i] == ',') {
      ++i;
      continue;
    }
    if (i < s.size() && s[i] == '}') break;
    fail("',' or '}'");
  }
  return file;
}

}  // namespace crumple::cli
