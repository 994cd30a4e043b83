// Regression (issue 45, defect 2): write_file_atomically renamed its temporary file over
// whatever was at the target (a device node, a FIFO, a symlink), and did not notice a write
// that failed for lack of space.
#include <crumple/core/atomic_file.hpp>
#include <crumple/core/error.hpp>
#include <support/temp_dir.hpp>

#include <gtest/gtest.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

namespace crumple {
namespace {

namespace fs = std::filesystem;

std::string contents(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void write_text(const fs::path& p, const std::string& text) {
  write_file_atomically(p, [&](std::ostream& out) { out << text; });
}

/// Only the target is in the folder afterwards (no temporary file left behind).
std::size_t entries(const fs::path& dir) {
  std::size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++n;
  return n;
}

/// The error message of `write_text(p, ...)`, which must throw ParseError.
std::string refusal(const fs::path& p) {
  try {
    write_text(p, "new\n");
  } catch (const ParseError& e) {
    EXPECT_EQ(e.file(), p.string());
    return e.what();
  }
  ADD_FAILURE() << "no error writing " << p;
  return {};
}

TEST(AtomicFile, WritesANewFileAndReplacesARegularOne) {
  testing::TempDir dir;
  const fs::path p = dir.path() / "out.txt";
  write_text(p, "first\n");
  EXPECT_EQ(contents(p), "first\n");
  fs::permissions(p, fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read);
  write_text(p, "second\n");
  EXPECT_EQ(contents(p), "second\n");
  EXPECT_EQ(fs::status(p).permissions() & fs::perms::all,
            fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read);
  EXPECT_EQ(entries(dir.path()), 1u);
}

TEST(AtomicFile, WritesThroughASymlinkToItsTarget) {
  testing::TempDir dir;
  fs::create_directories(dir.path() / "real");
  const fs::path target = dir.path() / "real" / "data.txt";
  std::ofstream(target) << "old\n";
  const fs::path link = dir.path() / "link.txt";
  fs::create_symlink(fs::path("real") / "data.txt", link);  // relative, as users make them
  write_text(link, "new\n");
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(link)));
  EXPECT_EQ(contents(target), "new\n");
  // A dangling link: the file it names is created.
  const fs::path dangling = dir.path() / "dangling.txt";
  fs::create_symlink(fs::path("real") / "later.txt", dangling);
  write_text(dangling, "made\n");
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(dangling)));
  EXPECT_EQ(contents(dir.path() / "real" / "later.txt"), "made\n");
}

TEST(AtomicFile, RefusesAFifoNamingIt) {
  testing::TempDir dir;
  const fs::path fifo = dir.path() / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string what = refusal(fifo);
  EXPECT_NE(what.find("FIFO"), std::string::npos) << what;
  EXPECT_EQ(fs::status(fifo).type(), fs::file_type::fifo);
  EXPECT_EQ(entries(dir.path()), 1u);
}

TEST(AtomicFile, RefusesADirectoryNamingIt) {
  testing::TempDir dir;
  const fs::path sub = dir.path() / "sub";
  fs::create_directories(sub);
  const std::string what = refusal(sub);
  EXPECT_NE(what.find("directory"), std::string::npos) << what;
  EXPECT_TRUE(fs::is_directory(sub));
  EXPECT_EQ(entries(dir.path()), 1u);
  // A symlink to a folder is refused the same way, and stays.
  fs::create_directory_symlink("sub", dir.path() / "to-sub");
  EXPECT_NE(refusal(dir.path() / "to-sub").find("directory"), std::string::npos);
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(dir.path() / "to-sub")));
}

TEST(AtomicFile, RefusesADeviceAndLeavesItInPlace) {
  // Before the fix, as root, `--contacts /dev/full` replaced the device node by a regular file.
  // The test never risks a real one: as root it makes its own node (a twin of /dev/null, major
  // 1 minor 3) in its folder; otherwise it uses /dev/full, which it cannot replace anyway.
  testing::TempDir dir;
  fs::path dev = dir.path() / "null-twin";
  if (::mknod(dev.c_str(), S_IFCHR | 0666, ::makedev(1, 3)) != 0) {
    dev = "/dev/full";
    if (!fs::exists(dev) || ::access("/dev", W_OK) == 0) GTEST_SKIP() << "no safe device node";
  }
  const std::string what = refusal(dev);
  EXPECT_NE(what.find("device"), std::string::npos) << what;
  EXPECT_EQ(fs::symlink_status(dev).type(), fs::file_type::character);
  // Through a symlink too.
  fs::create_symlink(dev, dir.path() / "link");
  EXPECT_NE(refusal(dir.path() / "link").find("device"), std::string::npos);
  EXPECT_EQ(fs::symlink_status(dev).type(), fs::file_type::character);
}

TEST(AtomicFile, AFailedWriteIsAnErrorAndKeepsTheOldFile) {
  // A file size limit makes write() fail with EFBIG, as a full disk fails with ENOSPC.
  testing::TempDir dir;
  const fs::path p = dir.path() / "big.txt";
  write_text(p, "old\n");
  rlimit saved{};
  ASSERT_EQ(::getrlimit(RLIMIT_FSIZE, &saved), 0);
  rlimit small = saved;
  small.rlim_cur = 4096;
  auto* previous = std::signal(SIGXFSZ, SIG_IGN);
  ASSERT_EQ(::setrlimit(RLIMIT_FSIZE, &small), 0);
  bool threw = false;
  try {
    write_text(p, std::string(1 << 20, 'x'));
  } catch (const ParseError& e) {
    threw = true;
    EXPECT_NE(std::string(e.what()).find("write"), std::string::npos) << e.what();
  }
  ::setrlimit(RLIMIT_FSIZE, &saved);
  std::signal(SIGXFSZ, previous);
  EXPECT_TRUE(threw);
  EXPECT_EQ(contents(p), "old\n");
  EXPECT_EQ(entries(dir.path()), 1u);
}

TEST(AtomicFile, AnExceptionFromTheWriterLeavesNothing) {
  testing::TempDir dir;
  const fs::path p = dir.path() / "x.txt";
  EXPECT_THROW(write_file_atomically(p, [](std::ostream&) { throw InputError("stop"); }), InputError);
  EXPECT_EQ(entries(dir.path()), 0u);
}

TEST(AtomicFile, AMissingFolderIsAnErrorNamingIt) {
  testing::TempDir dir;
  const std::string what = refusal(dir.path() / "no" / "such" / "x.txt");
  EXPECT_NE(what.find("no/such"), std::string::npos) << what;
}

}  // namespace
}  // namespace crumple
