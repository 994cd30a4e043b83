// support/run_cache.hpp, the tests' saved results: a value saved once reads back bit for bit
// without being computed again; a truncated file, or one saved by another program, is computed
// afresh, never trusted.
#include <crumple/detect/compare.hpp>
#include <crumple/detect/detector.hpp>
#include <support/run_cache.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace crumple {
namespace {

std::string text_of(const ReferenceRun& run) {
  std::ostringstream out;
  for (const ContactSet& c : run.contacts) write_contacts(out, c);
  return out.str();
}

TEST(RunCache, SavedOnceReadBackBitForBitAndDamagedFilesRecomputed) {
  using testing::run_cache_detail::cache_file;
  using testing::run_cache_detail::cached;
  const FoldingSequence seq({.n = 8, .frames = 12, .seed = 5});
  const Scalar h = 4 * seq.thickness();  // contacts from the first frames on, at this size
  const std::string key = "run-cache-test-" + std::to_string(::getpid());
  int computed = 0;
  const auto compute = [&] {
    ++computed;
    auto naive = make_detector(MethodSpec::parse("naive"), {.thickness = h});
    return run_reference(*naive, seq);
  };
  const ReferenceRun fresh = cached<ReferenceRun>(key, compute);
  ASSERT_EQ(computed, 1);
  std::size_t contacts = 0;
  for (const ContactSet& c : fresh.contacts) contacts += c.size();
  ASSERT_GT(contacts, 0u);
  const std::filesystem::path file = cache_file(key);
  ASSERT_TRUE(std::filesystem::is_regular_file(file)) << file;

  const ReferenceRun read = cached<ReferenceRun>(key, compute);
  EXPECT_EQ(computed, 1) << "read back, not computed";
  EXPECT_EQ(text_of(read), text_of(fresh));  // 17 significant digits: every double exactly
  EXPECT_EQ(read.ms, fresh.ms);

  // One byte short: computed again (and saved whole again).
  std::filesystem::resize_file(file, std::filesystem::file_size(file) - 1);
  EXPECT_EQ(text_of(cached<ReferenceRun>(key, compute)), text_of(fresh));
  EXPECT_EQ(computed, 2);
  EXPECT_EQ(text_of(cached<ReferenceRun>(key, compute)), text_of(fresh));
  EXPECT_EQ(computed, 2);

  // Saved by another program (the header's identity differs): computed again.
  std::string bytes;
  {
    std::ifstream in(file, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  const std::size_t at = bytes.find('\n') + 1;  // the program's path starts the second line
  bytes[at] = bytes[at] == 'x' ? 'y' : 'x';
  {
    std::ofstream out(file, std::ios::binary | std::ios::trunc);
    out << bytes;
  }
  EXPECT_EQ(text_of(cached<ReferenceRun>(key, compute)), text_of(fresh));
  EXPECT_EQ(computed, 3);
  std::filesystem::remove(file);
}

}  // namespace
}  // namespace crumple
