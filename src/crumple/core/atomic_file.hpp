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
///  - Only a regular file (which keeps its permission bits) or a new path is replaced. A
///    symbolic link is followed: the file it points to is written, the link stays. A directory,
///    device, FIFO or socket is refused before anything is written.
///  - Every write, the fsync and the close are checked: a full disk is an error, and the old
///    file stays as it was.
/// Throws `ParseError` naming `path` and the reason (the system's, where it gives one); the
/// temporary file is removed on any failure, including an exception thrown by `write` (which
/// is rethrown). `binary` is accepted for portability and has no effect on POSIX.
void write_file_atomically(const std::filesystem::path& path,
                           const std::function<void(std::ostream&)>& write, bool binary = false);

}  // namespace crumple
