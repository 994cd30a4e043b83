#pragma once
// Running another program (ffmpeg) without a shell: each argument reaches the program as given,
// so no file or folder name can be read as a command.

#include <filesystem>
#include <string>
#include <vector>

namespace crumple::cli {

/// Whether `program` is an executable file in one of PATH's folders.
bool on_path(const std::string& program);

/// Runs `argv[0]` (looked up on PATH) with the arguments `argv` in the folder `cwd`, stdin from
/// /dev/null, and waits for it. Returns its exit status; throws `Error` when it cannot be started
/// or is killed by a signal.
int run_program(const std::vector<std::string>& argv, const std::filesystem::path& cwd);

}  // namespace crumple::cli
