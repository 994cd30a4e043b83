#include "progress.hpp"

#include <cstdio>
#include <cstdlib>

#include <unistd.h>

namespace crumple::cli {

namespace {

std::string duration_text(double seconds) {
  const long s = static_cast<long>(seconds + 0.5);
  char buf[32];
  if (s >= 3600) {
    std::snprintf(buf, sizeof buf, "%ldh%02ldm", s / 3600, s / 60 % 60);
  } else if (s >= 60) {
    std::snprintf(buf, sizeof buf, "%ldm%02lds", s / 60, s % 60);
  } else {
    std::snprintf(buf, sizeof buf, "%lds", s);
  }
  return buf;
}

}  // namespace

Progress::Progress(std::string what, std::string unit, std::size_t total, bool enabled)
    : what_(std::move(what)),
      unit_(std::move(unit)),
      total_(total),
      enabled_(enabled),
      tty_(::isatty(STDERR_FILENO) != 0),
      start_(Clock::now()),
      last_(start_) {
  if (const char* env = std::getenv("CRUMPLE_PROGRESS_SECONDS")) {
    char* end = nullptr;
    const double v = std::strtod(env, &end);
    if (end != env && v >= 0) first_delay_s_ = period_s_ = v;
  }
}

Progress::~Progress() { finish(); }

void Progress::update(std::size_t done, const std::string& note) {
  if (!enabled_) return;
  const auto now = Clock::now();
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  const double since_last = std::chrono::duration<double>(now - last_).count();
  if (elapsed < first_delay_s_) return;
  if (drawn_ && !cleared_ && since_last < (tty_ ? 0.1 : period_s_)) return;
  cleared_ = false;
  last_ = now;
  std::string eta = "?";
  if (done > 0 && done <= total_) {
    eta = duration_text(elapsed / static_cast<double>(done) * static_cast<double>(total_ - done));
  }
  if (tty_) {
    constexpr std::size_t width = 30;
    const std::size_t filled = total_ > 0 ? std::min(width, done * width / total_) : width;
    std::fprintf(stderr, "\r\033[K[%s%s] %s %zu/%zu  %s elapsed, ETA %s%s%s",
                 std::string(filled, '#').c_str(), std::string(width - filled, '.').c_str(),
                 unit_.c_str(), done, total_, duration_text(elapsed).c_str(), eta.c_str(),
                 note.empty() ? "" : "  ", note.c_str());
  } else {
    std::fprintf(stderr, "crumple %s: %s %zu/%zu, %s elapsed, ETA %s%s%s\n", what_.c_str(),
                 unit_.c_str(), done, total_, duration_text(elapsed).c_str(), eta.c_str(),
                 note.empty() ? "" : ", ", note.c_str());
  }
  std::fflush(stderr);
  drawn_ = true;
}

void Progress::clear() {
  if (enabled_ && tty_ && drawn_) {
    std::fprintf(stderr, "\r\033[K");
    std::fflush(stderr);
    cleared_ = true;
  }
}

void Progress::finish() {
  clear();
  enabled_ = false;
}

}  // namespace crumple::cli
