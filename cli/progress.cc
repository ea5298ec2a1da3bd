#include "progress.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>

#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"

namespace transtick {

std::chrono::milliseconds Progress::LinesInterval() {
  // $TRANSTICK_PROGRESS_EVERY: seconds between lines when not on a terminal.
  if (const char* every = std::getenv("TRANSTICK_PROGRESS_EVERY")) {
    double s = 0;
    if (absl::SimpleAtod(every, &s) && std::isfinite(s) && s >= 0.01 && s <= 86400) {
      return std::chrono::milliseconds(std::llround(s * 1000));
    }
  }
  return std::chrono::seconds(5);
}

Progress::Style Progress::ForStderr(bool quiet) {
  if (quiet) return Style::kOff;
  return isatty(STDERR_FILENO) ? Style::kTerminal : Style::kLines;
}

Progress::Progress(Style style, std::chrono::milliseconds every, std::FILE* out)
    : style_(style), every_(every), out_(out) {}

Progress::~Progress() { Finish(); }

std::string Progress::Duration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  if (seconds < 60) return absl::StrFormat("%.1f s", seconds);
  const long s = std::lround(seconds);
  if (s < 3600) return absl::StrFormat("%d min %02d s", s / 60, s % 60);
  return absl::StrFormat("%d h %02d min", s / 3600, (s % 3600) / 60);
}

void Progress::Update(double fraction, const std::string& what) {
  if (style_ == Style::kOff) return;
  absl::MutexLock lock(&mu_);
  const auto now = std::chrono::steady_clock::now();
  fraction = std::clamp(fraction, 0.0, 1.0);
  if (!started_) {
    started_ = true;
    first_ = now;
    first_fraction_ = fraction;
    last_ = created_;
  }
  // In a log, the first line `every` after the command began, then one per `every`.
  if (style_ == Style::kLines && now - last_ < every_) return;
  last_ = now;
  const double elapsed = std::chrono::duration<double>(now - created_).count();
  const double measured = std::chrono::duration<double>(now - first_).count();
  const double gained = fraction - first_fraction_;
  // Too early an estimate misleads: none before 1% more or a quarter second.
  std::string eta = "time left ?";
  if (gained >= 0.01 && measured >= 0.25) {
    eta = "time left " + Duration(measured * (1 - fraction) / gained);
  }
  const std::string line =
      absl::StrFormat("%s: %5.1f%%, %s elapsed, %s", what, 100 * fraction, Duration(elapsed), eta);
  if (style_ == Style::kTerminal) {
    std::fprintf(out_, "\r\033[K%s", line.c_str());
    line_open_ = true;
  } else {
    std::fprintf(out_, "%s\n", line.c_str());
  }
  std::fflush(out_);
}

void Progress::ClearLocked() {
  if (line_open_) std::fprintf(out_, "\r\033[K");
  line_open_ = false;
}

void Progress::Say(const std::string& line) {
  if (style_ == Style::kOff) return;
  Warn(line);
}

void Progress::Warn(const std::string& line) {
  absl::MutexLock lock(&mu_);
  ClearLocked();
  std::fprintf(out_, "%s\n", line.c_str());
  std::fflush(out_);
}

void Progress::Finish() {
  absl::MutexLock lock(&mu_);
  ClearLocked();
  std::fflush(out_);
}

}  // namespace transtick
