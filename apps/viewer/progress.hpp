#pragma once
// Progress of long headless work (`--frames N` before the first picture) on stderr: nothing for
// the first two seconds, then at most one line a second with the frames done and an estimate of
// the time left — rewritten in place on a terminal, one plain line each otherwise. The
// environment variable CRUMPLE_PROGRESS_SECONDS sets both delays (as for `crumple`).

#include <crumple/core/timing.hpp>

#include <chrono>
#include <cstdio>
#include <cstdlib>

#include <unistd.h>

namespace crumple::viewer {

class Progress {
 public:
  Progress(const char* what, long long total) : what_(what), total_(total), tty_(isatty(fileno(stderr)) != 0) {
    if (const char* env = std::getenv("CRUMPLE_PROGRESS_SECONDS")) {
      char* end = nullptr;
      const double s = std::strtod(env, &end);
      if (end != env && s >= 0) quiet_ms_ = every_ms_ = 1000 * s;
    }
  }

  /// `done` of the total are finished.
  void update(long long done) {
    const double ms = ms_since(start_);
    if (ms < quiet_ms_ || ms - last_ms_ < every_ms_ || done <= 0) return;
    last_ms_ = ms;
    const double left_s = ms / 1000 * static_cast<double>(total_ - done) / static_cast<double>(done);
    std::fprintf(stderr, "%scrumple-view: %s %lld/%lld, %.0f s, about %.0f s left%s", tty_ ? "\r" : "", what_, done,
                 total_, ms / 1000, left_s, tty_ ? "\x1b[K" : "\n");
    printed_ = true;
  }
  /// Ends the line in place on a terminal, if one was printed.
  void finish() {
    if (printed_ && tty_) std::fprintf(stderr, "\n");
  }

 private:
  double quiet_ms_ = 2000, every_ms_ = 1000;
  const char* what_;
  long long total_;
  bool tty_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  double last_ms_ = 0;
  bool printed_ = false;
};

}  // namespace crumple::viewer
