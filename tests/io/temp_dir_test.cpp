// The tests' temporary folder (tests/support/temp_dir.hpp): every io and CLI test that writes
// files relies on it to start empty and to leave nothing behind.

#include <support/temp_dir.hpp>

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace crumple {
namespace {

namespace fs = std::filesystem;

TEST(TempDir, StartsEmptyAndIsRemovedWithItsContentWhenItDies) {
  fs::path where;
  {
    const testing::TempDir dir;
    where = dir.path();
    ASSERT_TRUE(fs::is_directory(where));
    EXPECT_TRUE(fs::is_empty(where));
    EXPECT_EQ(where.parent_path(), fs::temp_directory_path());
    // A file and a nested folder with a file, as the CLI's outputs leave them.
    std::ofstream(dir / "a.txt") << "a";
    fs::create_directories(dir / "frames" / "deeper");
    std::ofstream(dir / "frames" / "deeper" / "b.txt") << "b";
    ASSERT_TRUE(fs::exists(dir / "frames" / "deeper" / "b.txt"));
  }
  EXPECT_FALSE(fs::exists(where)) << where << " outlived its TempDir";
}

TEST(TempDir, TwoFoldersOfOneTestAreDistinctAndNamedAfterIt) {
  const testing::TempDir first, second;
  EXPECT_NE(first.path(), second.path());
  for (const auto* dir : {&first, &second}) {
    const std::string name = dir->path().filename().string();
    EXPECT_NE(name.find("TempDir.TwoFoldersOfOneTestAreDistinctAndNamedAfterIt"), std::string::npos) << name;
  }
  // Removing one leaves the other alone.
  fs::path gone;
  {
    const testing::TempDir third;
    gone = third.path();
  }
  EXPECT_FALSE(fs::exists(gone));
  EXPECT_TRUE(fs::is_directory(first.path()));
  EXPECT_TRUE(fs::is_directory(second.path()));
}

}  // namespace
}  // namespace crumple
