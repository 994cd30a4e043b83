#pragma once
// Progress of long runs on stderr: a redrawn bar with an ETA on a terminal, a plain line every
// few seconds otherwise (logs, CI). Nothing for runs shorter than a couple of seconds.

#include <chrono>
#include <cstddef>
#include <string>

namespace crumple::cli {

class Progress {
 public:
  /// `what` names the work ("simulate", "render"), `unit` its items ("frame"); `total` items.
  /// Disabled when `enabled` is false. The environment variable CRUMPLE_PROGRESS_SECONDS sets
  /// the delay before the first report and between plain lines (default 2 and 5 s).
  Progress(std::string what, std::string unit, std::size_t total, bool enabled = true);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  /// `done` items of `total` are finished; `note` says what runs now (may be empty).
  void update(std::size_t done, const std::string& note = {});
  /// Clears the bar (terminal) so other output starts on a clean line; the next update redraws.
  void clear();
  /// Clears the bar and reports nothing more; idempotent.
  void finish();

 private:
  using Clock = std::chrono::steady_clock;
  std::string what_, unit_;
  std::size_t total_;
  bool enabled_;
  bool tty_;
  bool drawn_ = false;
  bool cleared_ = false;  ///< the bar was cleared for other output
  double first_delay_s_ = 2, period_s_ = 5;
  Clock::time_point start_, last_;
};

}  // namespace crumple::cli
