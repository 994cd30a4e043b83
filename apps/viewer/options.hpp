#pragma once
// crumple-view's command line, as parsed by main.cpp.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace crumple::viewer {

/// The viewer's default detection method: the fast exact one (the same contacts as `naive`).
inline constexpr const char* kDefaultMethod = "kdop";

struct Options {
  std::string input = "hanging-cloth";  ///< scene spec, mesh / MassSpring file or frame folder
  std::vector<std::string> params;      ///< scene `key=value` items
  long long frames = 0;                 ///< frames to advance before the first picture
  std::string screenshot;
  bool exit = false;
  std::string size = "1024x720";
  std::optional<std::string> method;  ///< default: kDefaultMethod
  std::optional<double> thickness;    ///< default: the scene's, or the frames' default thickness
  std::uint64_t seed = 1;
  bool wireframe = false;
  bool springs = false;
  bool active_pairs = false;
  int kdop_level = -1;
  bool recall = false;
  std::optional<bool> response;        ///< default: the scene's
  std::optional<bool> untangle;        ///< default: on (`sim::Settings::untangle`)
  long long response_from = -1;        ///< frames before it run with the response off (-1: none)
};

}  // namespace crumple::viewer
