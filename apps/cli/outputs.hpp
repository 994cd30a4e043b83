#pragma once
// Output paths are checked before any work, so a typo costs no minutes of computation, and a
// file system error reads as a user error with the OS's reason.

#include <filesystem>
#include <string>

namespace crumple::cli {

/// Creates the folder `dir` (and its parents) for the output given by `option` (e.g. "--out").
/// Throws `InputError` with the OS's reason when a file is in the way, it cannot be created or
/// it is not writable.
void prepare_output_folder(const std::filesystem::path& dir, const std::string& option);

/// Checks that the file `file` can be written for `option`: not a folder, its folder exists (or
/// is created) and is writable. Throws `InputError` otherwise.
void check_output_file(const std::filesystem::path& file, const std::string& option);

}  // namespace crumple::cli
