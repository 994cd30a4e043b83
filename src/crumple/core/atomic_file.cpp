#include <crumple/core/atomic_file.hpp>
#include <crumple/core/error.hpp>

#include <atomic>
#include <fstream>
#include <string>
#include <system_error>

#include <unistd.h>

namespace crumple {

namespace {
std::filesystem::path temporary_name(const std::filesystem::path& path) {
  static std::atomic<unsigned> counter{0};
  // Built with append: `"." + std::string` chains trip a GCC 12 -Wrestrict false positive.
  std::string name(".");
  name.append(path.filename().string())
      .append(".tmp.")
      .append(std::to_string(::getpid()))
      .append(".")
      .append(std::to_string(counter.fetch_add(1)));
  return path.parent_path() / name;
}
}  // namespace

void write_file_atomically(const std::filesystem::path& path,
                           const std::function<void(std::ostream&)>& write, bool binary) {
  const std::filesystem::path tmp = temporary_name(path);
  const auto fail = [&](const std::string& what) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw ParseError(path.string(), {}, what);
  };
  {
    std::ofstream out(tmp, binary ? std::ios::binary | std::ios::trunc : std::ios::trunc);
    if (!out) fail("cannot open a temporary file for writing in " + path.parent_path().string());
    try {
      write(out);
    } catch (...) {
      out.close();
      std::error_code ignored;
      std::filesystem::remove(tmp, ignored);
      throw;
    }
    out.flush();
    if (!out) fail("write failed (disk full?)");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) fail("cannot rename the temporary file into place: " + ec.message());
}

}  // namespace crumple
