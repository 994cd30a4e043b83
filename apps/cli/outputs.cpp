#include "outputs.hpp"

#include <crumple/core/error.hpp>

#include <cerrno>
#include <cstring>
#include <system_error>

#include <unistd.h>

namespace crumple::cli {

namespace {

std::string quoted(const std::filesystem::path& p) {
  std::string out(1, '\'');
  out.append(p.string()).push_back('\'');
  return out;
}

}  // namespace

void prepare_output_folder(const std::filesystem::path& dir, const std::string& option) {
  const std::filesystem::path target = dir.empty() ? "." : dir;
  std::error_code ec;
  const auto status = std::filesystem::status(target, ec);
  if (std::filesystem::exists(status) && !std::filesystem::is_directory(status)) {
    throw InputError(option + " " + quoted(dir) + " is not a folder");
  }
  if (!std::filesystem::exists(status)) {
    std::filesystem::create_directories(target, ec);
    if (ec) {
      throw InputError(option + ": cannot create the folder " + quoted(dir) + ": " + ec.message());
    }
  }
  if (::access(target.c_str(), W_OK | X_OK) != 0) {
    throw InputError(option + ": cannot write into " + quoted(dir) + ": " + std::strerror(errno));
  }
}

void check_output_file(const std::filesystem::path& file, const std::string& option) {
  std::error_code ec;
  if (file.empty()) throw InputError(option + " needs a file name");
  if (std::filesystem::is_directory(file, ec)) {
    throw InputError(option + " " + quoted(file) + " is a folder, not a file");
  }
  prepare_output_folder(file.has_parent_path() ? file.parent_path() : ".", option);
}

}  // namespace crumple::cli
