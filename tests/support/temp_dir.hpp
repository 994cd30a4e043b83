#pragma once
// A temporary folder for a test, shared by every suite that writes files (io, CLI).

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <unistd.h>

namespace crumple::testing {

/// A fresh, empty folder under the system temporary folder, removed with everything in it when
/// the object goes out of scope, so a test that fails half-way leaves nothing behind either.
/// Its name holds the process id, the running test's name and a counter, so two tests,
/// two folders of one test, or two processes running the suite at once never share one. It
/// cannot be copied: one folder, one owner.
class TempDir {
 public:
  TempDir() {
    std::string name = "crumple-";
    name += std::to_string(::getpid());
    if (const auto* info = ::testing::UnitTest::GetInstance()->current_test_info()) {
      name += '-';
      name += info->test_suite_name();
      name += '.';
      name += info->name();
    }
    static int counter = 0;
    name += '-';
    name += std::to_string(counter++);
    for (char& c : name) {
      if (c == '/') c = '_';  // parameterised tests' names hold slashes
    }
    path_ = std::filesystem::temp_directory_path() / name;
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

}  // namespace crumple::testing
