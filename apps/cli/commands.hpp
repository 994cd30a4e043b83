#pragma once
// Subcommands of the `crumple` tool. Each `add_*` registers its options on the app and returns
// the function to run when the subcommand is chosen. Apps parse, call the library, print.

#include <CLI/CLI.hpp>

#include <functional>

namespace crumple::cli {

using Run = std::function<int()>;

Run add_detect_command(CLI::App& app);
Run add_compare_command(CLI::App& app);
Run add_info_command(CLI::App& app);
Run add_simulate_command(CLI::App& app);
Run add_bench_command(CLI::App& app);
Run add_render_command(CLI::App& app);
Run add_ccd_command(CLI::App& app);

}  // namespace crumple::cli
