#pragma once
/// \file
/// Atomic file output: content goes to a temporary file beside the target, which is renamed
/// over the target only once fully written and flushed. An interrupted write leaves the old
/// file (or none), never a half-written one.

#include <filesystem>
#include <functional>
#include <ostream>

namespace crumple {

/// Calls `write(stream)` on a temporary file in the target's folder, then renames it to `path`.
/// Throws `ParseError` (with the file name) if the file cannot be opened or written; the
/// temporary file is removed on any failure, including an exception thrown by `write`.
/// `binary` opens the stream in binary mode.
void write_file_atomically(const std::filesystem::path& path,
                           const std::function<void(std::ostream&)>& write, bool binary = false);

}  // namespace crumple
