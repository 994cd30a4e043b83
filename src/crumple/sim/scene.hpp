#pragma once
/// \file
/// Built-in, parameterised, deterministic scenes shared by the CLI, the benchmarks and the
/// tests, named by a spec `NAME[:key=value,...]` (e.g. `hanging-cloth:nx=20,ny=20`), plus
/// scenes made from a mesh or a mass–spring model read from a file (the `file` entry's keys).
/// The same spec and seed always give the same scene, bit for bit.
///
/// Lengths in metres, masses in kilograms, times in seconds; y is up.

#include <crumple/response/obstacle.hpp>
#include <crumple/sim/simulation.hpp>

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace crumple::sim {

struct SceneParamInfo {
  std::string_view key;
  std::string_view default_value;
  std::string_view description;
};

struct SceneInfo {
  std::string_view name;
  std::string_view summary;
  std::span<const SceneParamInfo> params;
};

/// Every built-in scene, then the `file` entry (keys for meshes read from files).
std::span<const SceneInfo> all_scenes();
/// Throws `InputError` listing the valid names.
const SceneInfo& scene_info(std::string_view name);

/// A scene name and its parameters. Keys are checked against the scene's table.
class SceneSpec {
 public:
  /// Parses `NAME[:key=value,...]`; unknown names or keys, a key given twice or an item without
  /// '=' throw `InputError` listing the valid names or keys.
  static SceneSpec parse(std::string_view text);
  const std::string& name() const { return name_; }
  const std::vector<std::pair<std::string, std::string>>& params() const { return params_; }
  /// Sets or replaces a parameter (key checked).
  SceneSpec& set(std::string key, std::string value);
  /// Value given, else the table's default; malformed values throw `InputError` naming the key.
  Scalar get_double(std::string_view key) const;
  long long get_int(std::string_view key) const;
  bool get_bool(std::string_view key) const;
  std::string get_string(std::string_view key) const;
  /// Canonical text; `parse(to_string())` gives the same spec.
  std::string to_string() const;

 private:
  std::string name_;
  std::vector<std::pair<std::string, std::string>> params_;
};

/// A ready-to-run scene: the cloth, its environment and the suggested settings.
struct Scene {
  std::string spec;  ///< canonical spec it was made from
  Model model;
  State state;
  ForceField field;
  std::vector<response::Obstacle> obstacles;
  Kinematics kinematics;  ///< may be empty
  /// Suggested settings (the CLI's defaults): dt, substeps, integrator, thickness, response.
  Settings settings;
  Scalar edge_length = 0;  ///< mean rest length of the mesh edges (m)
};

/// Builds a built-in scene. `seed` drives the scene's random perturbation.
Scene make_scene(const SceneSpec& spec, std::uint64_t seed);

/// A cloth from a mesh read from a file, with the `file` keys of `params` (pins, material,
/// gravity, ...). `params.name()` must be "file".
Scene make_scene_from_mesh(const TriMesh& mesh, const SceneSpec& params);
/// A scene around an existing model and state (an X3D `MassSpring` node): gravity, air damping
/// and the suggested settings from the `file` keys of `params`; the cloth keys are ignored.
Scene make_scene_from_model(Model model, State state, const SceneSpec& params);

/// Frames of one simulated built-in scene, with the share of edges in collision of each.
struct Recording {
  std::string spec;  ///< canonical scene spec
  TriMesh mesh;      ///< topology and the first frame
  std::vector<Positions> frames;
  std::vector<double> share;  ///< `collision_share` of each frame (VF + EE contacts)
  Scalar thickness = 0;       ///< the scene's contact thickness
};

/// Simulates the built-in scene `spec` for `frames` frames with its suggested settings (frame 0
/// is the initial state, so `frames + 1` are kept). Detection during the recording uses the
/// exact `kdop` detector on one thread, so the frames do not depend on the machine.
/// `on_frame(k)` is called after frame k (progress).
Recording record_scene(const std::string& spec, std::int64_t frames, std::uint64_t seed,
                       const std::function<void(std::int64_t)>& on_frame = {});

}  // namespace crumple::sim
