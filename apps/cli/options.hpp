#pragma once
// What the subcommands share: the detection options (method, thickness, kinds, threads, contact
// budget) with one rule for each default, the list of frame files from files and folders, and
// the checks that keep a typo from costing gigabytes.

#include <crumple/detect/detector.hpp>
#include <crumple/mesh/mesh.hpp>

#include <CLI/CLI.hpp>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace crumple::cli {

/// The method every subcommand uses when none is given: the fast exact detector. `naive` is the
/// reference (`crumple compare --against`).
inline constexpr const char* kDefaultMethod = "kdop";
/// Largest `--threads`.
inline constexpr int kMaxThreads = 1024;
/// Default `--max-contacts`: about 2 GB of contact records at the detectors' peak.
inline constexpr long long kDefaultMaxContacts = 10'000'000;

struct DetectionArgs {
  std::optional<std::string> method;
  std::optional<double> thickness;
  std::optional<double> thickness_rel;
  std::optional<std::string> kinds;
  int threads = 0;
  long long max_contacts = kDefaultMaxContacts;
};

/// What the thickness defaults to, for the help text of --thickness.
struct DetectionHelp {
  std::string method_default = kDefaultMethod;  ///< shown in --method's help
  std::string thickness_default;                ///< shown in --thickness's help
  bool max_contacts = true;                     ///< whether --max-contacts is offered
};

/// Registers -m/--method, -t/--thickness, -r/--thickness-rel, -k/--kinds, -j/--threads and
/// --max-contacts on `app`.
void add_detection_options(CLI::App& app, DetectionArgs& args, const DetectionHelp& help);

/// Every method with its parameters, for --help.
std::string methods_help();

/// --method, else `fallback` (else `kDefaultMethod`).
MethodSpec method_of(const DetectionArgs& args, std::optional<MethodSpec> fallback = {});

/// The thickness: --thickness, else --thickness-rel × the bounding-box diagonal of `first`, else
/// `own` (a scene's or a built-in sequence's), else `default_thickness(first)`. Throws
/// `InputError` unless it is finite and >= 0.
Scalar thickness_of(const DetectionArgs& args, PositionsView first, std::optional<Scalar> own = {});

/// Checks --threads (0..kMaxThreads) and --max-contacts (>= 0); throws `InputError`.
void check_detection_args(const DetectionArgs& args);

/// Detector options from the shared options (thickness as `thickness_of`).
DetectorOptions detector_options(const DetectionArgs& args, PositionsView first,
                                 std::optional<Scalar> own = {});

/// Warns (stderr) when the thickness is a large fraction of the mesh, and throws `InputError`
/// when the contacts it would produce, estimated on a sample of vertices and edges, exceed
/// `max_contacts` (0 = no limit): such a thickness makes nearly every pair a contact and the
/// detection would run out of memory.
void check_contact_budget(const Topology& topology, PositionsView x, const DetectorOptions& options,
                          long long max_contacts);

/// The frame files of `inputs`, in order: a file as is, a folder as its .obj .ply .off .x3d
/// files sorted by name. Throws `InputError` for a missing path or a folder without frames.
std::vector<std::filesystem::path> frame_files(const std::vector<std::string>& inputs);

}  // namespace crumple::cli
